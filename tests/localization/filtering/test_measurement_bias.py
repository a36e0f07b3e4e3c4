"""The AR(1) measurement bias: no bias reduces to the plain EKF, a correlated noise that makes
the plain EKF over-confident is consistent with the bias state, snapshots restore it all,
and the option's inputs."""

from __future__ import annotations

import numpy as np
import pytest

from envs.motion_model import UnicycleModel, wrap_angle
from localization.filtering.ekf import PoseEKF, PoseMeasurement, pose_residual
from localization.filtering.measurement_bias import (
    BiasedPoseEKF,
    MeasurementBias,
    make_ekf,
    measurement_bias_for,
)

R_MODEL = np.diag([0.1, 0.1, 0.03]) ** 2
Q = np.diag([0.01, 0.01, 0.005]) ** 2
P0 = np.diag([0.1, 0.1, 0.03]) ** 2


def test_no_bias_is_the_plain_ekf():
    """rho = 0: the same means, covariances and NIS as PoseEKF, to rounding."""
    rng = np.random.default_rng(0)
    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    plain = PoseEKF(F, Q, np.zeros(3), P0)
    biased = BiasedPoseEKF(F, Q, np.zeros(3), P0, bias=MeasurementBias(rho=0.0, phi=0.5))
    for _ in range(30):
        u = np.array([1.0, 0.3])
        z = plain.x + 0.1 * rng.standard_normal(3)
        for ekf in (plain, biased):
            ekf.predict(u)
        a, b = plain.update(z, model), biased.update(z, model)
        assert a.nis == pytest.approx(b.nis) and a.accepted == b.accepted
        np.testing.assert_allclose(biased.x, plain.x, atol=1e-12)
        np.testing.assert_allclose(biased.P, plain.P, atol=1e-12)


def _nees(bias: MeasurementBias | None, seed: int) -> float:
    """Mean NEES of a pose-measurement EKF whose noise R_MODEL is 60 % an AR(1) bias of
    per-step correlation 0.8 (the filter's R is the right total)."""
    rng = np.random.default_rng(seed)
    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    std, rho, phi = np.sqrt(np.diag(R_MODEL)), 0.6, 0.8
    x, b = np.zeros(3), np.sqrt(rho) * std * rng.standard_normal(3)
    ekf = make_ekf(F, Q, x, P0, None, bias)
    nees = []
    for _ in range(600):
        u = np.array([1.0, 0.2])
        x = F.predict(x, u) + np.sqrt(np.diag(Q)) * rng.standard_normal(3)
        x[2] = wrap_angle(x[2])
        b = phi * b + np.sqrt((1 - phi ** 2) * rho) * std * rng.standard_normal(3)
        z = x + b + np.sqrt(1 - rho) * std * rng.standard_normal(3)
        ekf.predict(u)
        ekf.update(z, model)
        e = pose_residual(x, ekf.x)
        nees.append(e @ np.linalg.solve(ekf.P, e))
    return float(np.mean(nees[50:]))


def test_a_persistent_bias_is_consistent_with_the_bias_state():
    """Measured (seeds 0-4): plain 6.7-9.1, with the true rho and phi 2.5-3.5, with the
    defaults (rho 0.45, phi 0.65: too little) 3.9-5.0. A consistent filter reads 3; one run's
    time average of correlated NEES values spreads wider than the independent band."""
    for seed in range(3):
        plain = _nees(None, seed)
        biased = _nees(MeasurementBias(rho=0.6, phi=0.8), seed)
        assert plain > 5.5
        assert 2.0 < biased < 4.0 and biased < 0.6 * plain
        assert _nees(MeasurementBias(), seed) < plain


def test_snapshot_restores_pose_and_bias():
    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    ekf = BiasedPoseEKF(F, Q, np.zeros(3), P0)
    ekf.predict(np.array([1.0, 0.0]))
    ekf.update(np.array([0.12, 0.02, 0.01]), model)
    state = ekf.snapshot()
    before = [np.copy(a) for a in (ekf.x, ekf.P, ekf.b, ekf.P_bb, ekf.P_xb)]
    ekf.predict(np.array([1.0, 0.5]))
    ekf.update(np.array([0.3, 0.1, 0.05]), model)
    ekf.restore(state)
    for a, b in zip(before, (ekf.x, ekf.P, ekf.b, ekf.P_bb, ekf.P_xb)):
        np.testing.assert_array_equal(a, b)


def test_an_indefinite_joint_covariance_forgets_the_cross_terms():
    """P shrunk from outside (a caller setting P) would make [[P, P_xb], [., P_bb]]
    indefinite: the update drops P_xb instead of failing."""
    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    ekf = BiasedPoseEKF(F, Q, np.zeros(3), P0)
    ekf.update(np.array([0.05, 0.0, 0.0]), model)
    ekf.P_xb = np.full((3, 3), 0.05)
    ekf.P = 1e-6 * np.eye(3)
    assert ekf.update(np.array([0.0, 0.0, 0.0]), model).accepted
    assert np.all(np.linalg.eigvalsh(ekf.P) > 0)


@pytest.mark.parametrize("option, error, match", [
    ("yes", TypeError, "measurement_bias must be"),
    ({"rho": 1.0}, ValueError, "rho"),
    ({"phi": -0.1}, ValueError, "phi"),
    ({"lag": 3}, TypeError, "lag"),
])
def test_bad_options_are_named(option, error, match):
    with pytest.raises(error, match=match):
        measurement_bias_for(option)


def test_options():
    assert measurement_bias_for(False) is None
    assert measurement_bias_for(True) == MeasurementBias(rho=0.45, phi=0.65)
    bias = MeasurementBias(rho=0.2)
    assert measurement_bias_for(bias) == bias
    assert measurement_bias_for({"phi": 0.9}).phi == 0.9
    assert type(make_ekf(UnicycleModel(dt=0.1), Q, np.zeros(3), P0, 0.997, None)) is PoseEKF


def test_heading_inflation_keeps_the_joint_covariance():
    """BeliefFilter's heading inflation scales P's heading row and column and P_xb's heading
    row alike (a congruence): the joint covariance stays positive semi-definite and the
    cross-covariance is kept, not dropped at the next update."""
    from localization.filtering._belief_recovery import RecoveryMixin

    F, model = UnicycleModel(dt=0.1), PoseMeasurement(R_MODEL)
    ekf = BiasedPoseEKF(F, Q, np.zeros(3), P0)
    for z in ([0.05, 0.0, 0.01], [0.1, 0.01, 0.0]):
        ekf.predict(np.array([1.0, 0.2]))
        ekf.update(np.array(z), model)
    host = RecoveryMixin()
    host.ekf, host.inflate_factor = ekf, 4.0
    P_xb = ekf.P_xb.copy()
    host._inflate_heading()
    np.testing.assert_allclose(ekf.P_xb[:2], P_xb[:2])
    np.testing.assert_allclose(ekf.P_xb[2], 2.0 * P_xb[2])
    Pa = np.block([[ekf.P, ekf.P_xb], [ekf.P_xb.T, ekf.P_bb]])
    assert np.linalg.eigvalsh(Pa)[0] > -1e-12
    kept = ekf.P_xb.copy()
    ekf._joint(3, R_MODEL)  # the update's check: nothing to repair
    np.testing.assert_array_equal(ekf.P_xb, kept)


def test_the_bias_is_the_maps_not_the_frames():
    """A model whose R is inflated for this frame (its gate_R the place's R): the bias's
    stationary covariance is rho gate_R, the inflation goes to the white part only."""
    from localization.filtering.adaptive_noise import ScaledMeasurement

    F = UnicycleModel(dt=0.1)
    inflated = ScaledMeasurement(PoseMeasurement(R_MODEL), 9.0)  # R = 9 R_MODEL, gate R_MODEL
    ekf = BiasedPoseEKF(F, Q, np.zeros(3), P0, bias=MeasurementBias(rho=0.5, phi=0.5))
    ekf.update(np.array([0.05, 0.0, 0.0]), inflated)
    ekf.predict(np.array([1.0, 0.0]))
    np.testing.assert_allclose(ekf._R_b, 0.5 * R_MODEL)
    assert np.all(np.diag(ekf.P_bb) < R_MODEL.diagonal())  # never the inflated 9 R
    plain = BiasedPoseEKF(F, Q, np.zeros(3), P0, bias=MeasurementBias(rho=0.5, phi=0.5))
    plain.update(np.array([0.05, 0.0, 0.0]), PoseMeasurement(9.0 * R_MODEL))
    assert np.all(np.diag(plain.P_bb) > np.diag(ekf.P_bb))  # without gate_R: the model's R
