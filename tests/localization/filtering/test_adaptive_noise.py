"""Innovation-adaptive R: the running scale, the scaled model in the EKF, a filter that is
consistent where a too-small R is not, and the belief option's inputs."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from envs.motion_model import UnicycleModel, wrap_angle
from localization.filtering.adaptive_noise import (
    InnovationScale,
    ScaledMeasurement,
    innovation_scale,
)
from localization.filtering.ekf import FunctionMeasurement, PoseEKF, PoseMeasurement, pose_residual

R_MODEL = np.diag([0.1, 0.1, 0.03]) ** 2
Q = np.diag([0.01, 0.01, 0.005]) ** 2


def test_scale_follows_the_innovations_within_its_bounds():
    s = InnovationScale(rate=0.5, max_scale=4.0)
    assert s.scale == 1.0
    s.record(0.3, 3, 11.3)  # smaller innovations than predicted: R never shrinks
    assert s.mean < 1.0 and s.scale == 1.0
    for _ in range(20):
        s.record(9.0, 3, 11.3)
    assert s.mean == pytest.approx(3.0, rel=1e-3) and s.scale == pytest.approx(3.0, rel=1e-3)
    for _ in range(20):
        s.record(1e6, 3, 11.3)  # an outlier counts at the gate
    assert s.mean == pytest.approx(11.3 / 3, rel=1e-3) and s.scale == pytest.approx(11.3 / 3, rel=1e-3)
    s.record(np.nan, 3, 11.3)
    assert s.mean == pytest.approx(11.3 / 3, rel=1e-3)
    s.max_scale = 2.0
    assert s.scale == 2.0
    s.reset()
    assert s.mean == 1.0


def test_scaled_model_weighs_by_the_scaled_R_and_gates_by_the_model_R():
    F = UnicycleModel(dt=0.1)
    base = PoseMeasurement(R_MODEL)
    z = np.array([0.15, -0.05, 0.02])
    plain, scaled, reference = (PoseEKF(F, Q, np.zeros(3), np.diag([0.2, 0.2, 0.05]) ** 2)
                                for _ in range(3))
    r_plain = plain.update(z, base)
    r_scaled = scaled.update(z, ScaledMeasurement(base, 4.0))
    reference.update(z, PoseMeasurement(4.0 * R_MODEL))
    np.testing.assert_allclose(scaled.x, reference.x)
    np.testing.assert_allclose(scaled.P, reference.P)
    assert r_scaled.nis == pytest.approx(r_plain.nis)  # the gate's NIS: the model's R
    assert not np.allclose(scaled.x, plain.x)
    np.testing.assert_allclose(ScaledMeasurement(base, 4.0).R, 4.0 * R_MODEL)
    varying = FunctionMeasurement(lambda x: x, lambda x: np.eye(3), lambda x: (1 + x[0] ** 2) * R_MODEL)
    scaled = ScaledMeasurement(varying, 2.0)
    x = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(scaled.R_at(x), 4.0 * R_MODEL)  # 2 x (1 + 1) R
    np.testing.assert_allclose(scaled.R(x), 4.0 * R_MODEL)
    np.testing.assert_allclose(scaled.gate_R(x), 2.0 * R_MODEL)
    assert copy.copy(scaled).scale == 2.0


def _nees(adaptive: bool, seed: int) -> float:
    """Mean NEES of a pose-measurement EKF whose R is 9x too small (true std 3x R_MODEL's)."""
    rng = np.random.default_rng(seed)
    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    scale = InnovationScale() if adaptive else None
    x = np.zeros(3)
    ekf = PoseEKF(F, Q, x, np.diag([0.1, 0.1, 0.03]) ** 2, gate_probability=None)
    nees = []
    for _ in range(400):
        u = np.array([1.0, 0.2])
        x = F.predict(x, u) + np.sqrt(np.diag(Q)) * rng.standard_normal(3)
        x[2] = wrap_angle(x[2])
        z = x + 3.0 * np.sqrt(np.diag(R_MODEL)) * rng.standard_normal(3)
        ekf.predict(u)
        r = ekf.update(z, model if scale is None else scale.wrap(model))
        if scale is not None:
            scale.record(r.nis, r.dim_z, r.threshold)
        e = pose_residual(x, ekf.x)
        nees.append(e @ np.linalg.solve(ekf.P, e))
    return float(np.mean(nees[50:]))


def test_a_too_small_R_is_scaled_to_consistency():
    """Measured (seeds 0-4): plain 14.5-19.2 (a consistent filter reads 3), adaptive
    3.4-4.9."""
    for seed in range(3):
        plain, adaptive = _nees(False, seed), _nees(True, seed)
        assert plain > 10.0
        assert adaptive < 6.5 and adaptive < 0.4 * plain


@pytest.mark.parametrize("option, error, match", [
    ("yes", TypeError, "adaptive_noise must be"),
    ({"rate": 0.0}, ValueError, "rate"),
    ({"rate": 1.5}, ValueError, "rate"),
    ({"max_scale": 0.5}, ValueError, "max_scale"),
    ({"window": 3}, TypeError, "window"),
])
def test_bad_options_are_named(option, error, match):
    with pytest.raises(error, match=match):
        innovation_scale(option)


def test_options():
    assert innovation_scale(False) is None
    assert isinstance(innovation_scale(True), InnovationScale)
    s = InnovationScale(rate=0.2)
    copy = innovation_scale(s)
    assert copy is not s and (copy.rate, copy.max_scale) == (s.rate, s.max_scale)
    assert innovation_scale({"rate": 0.2, "max_scale": 3.0}).max_scale == 3.0
