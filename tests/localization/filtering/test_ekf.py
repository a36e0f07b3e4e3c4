"""Tests of the pose EKF (localization/filters.py): accuracy, consistency, gating, wrapping, inputs."""

from __future__ import annotations

import numpy as np
import pytest

from envs.motion_model import UnicycleModel, wrap_angle
from localization.filtering.ekf import (
    FunctionMeasurement,
    PoseEKF,
    PoseMeasurement,
    UpdateResult,
    chi2_band,
    control_noise_Q,
    numerical_jacobian,
    pose_residual,
)

DT = 0.1
Q_TRUE = np.diag([0.02, 0.02, 0.01]) ** 2
R_POSE = np.diag([0.3, 0.3, 0.1]) ** 2
P0 = np.diag([0.2, 0.2, 0.05]) ** 2


def controls(n: int, rng: np.random.Generator) -> np.ndarray:
    """Smoothly varying [v, w] sequence, shape (n, 2)."""
    t = np.arange(n) * DT
    phase = rng.uniform(0, 2 * np.pi)
    return np.column_stack([1.0 + 0.3 * np.sin(0.5 * t + phase), 0.6 * np.sin(0.3 * t + phase)])


def simulate(model: UnicycleModel, x0: np.ndarray, U: np.ndarray, Q: np.ndarray,
             rng: np.random.Generator) -> np.ndarray:
    """True poses after each control with additive process noise N(0, Q), shape (n, 3)."""
    L = np.linalg.cholesky(Q)
    x, out = x0.copy(), []
    for u in U:
        x = model.predict(x, u) + L @ rng.standard_normal(3)
        x[2] = wrap_angle(x[2])
        out.append(x)
    return np.array(out)


def dead_reckoning(model: UnicycleModel, x0: np.ndarray, U: np.ndarray) -> np.ndarray:
    x, out = x0.copy(), []
    for u in U:
        x = model.predict(x, u)
        out.append(x)
    return np.array(out)


def run_filter(model: UnicycleModel, x_est0: np.ndarray, U: np.ndarray, Z: np.ndarray, meas,
               gate_probability: float | None = 0.997) -> tuple[np.ndarray, list[UpdateResult]]:
    """Predict/update over a sequence; estimates after each update (n, 3) and update results."""
    ekf = PoseEKF(model, Q_TRUE, x_est0, P0, gate_probability=gate_probability)
    est, results = [], []
    for u, z in zip(U, Z):
        ekf.predict(u)
        results.append(ekf.update(z, meas))
        est.append(ekf.x.copy())
    return np.array(est), results


def pos_rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((a[..., :2] - b[..., :2]) ** 2, axis=-1))))


# ----------------------------------------------------------------------------- (1) pose measurements
def test_pose_measurements_accuracy_and_consistency() -> None:
    rng = np.random.default_rng(0)
    model, meas = UnicycleModel(DT), PoseMeasurement(R_POSE)
    n_runs, n_steps = 50, 200
    nees = np.empty((n_runs, n_steps))
    nis = np.empty((n_runs, n_steps))
    err = {"ekf": [], "dr": [], "raw": []}
    for r in range(n_runs):
        x0 = np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
        x_est0 = x0 + np.linalg.cholesky(P0) @ rng.standard_normal(3)
        U = controls(n_steps, rng)
        X = simulate(model, x0, U, Q_TRUE, rng)
        Z = X + rng.multivariate_normal(np.zeros(3), R_POSE, size=n_steps)
        Z[:, 2] = wrap_angle(Z[:, 2])
        ekf = PoseEKF(model, Q_TRUE, x_est0, P0)
        est = []
        for k in range(n_steps):
            ekf.predict(U[k])
            res = ekf.update(Z[k], meas)
            nis[r, k] = res.nis
            nees[r, k] = ekf.nees(X[k])
            est.append(ekf.x.copy())
        err["ekf"].append(pos_rmse(np.array(est), X))
        err["dr"].append(pos_rmse(dead_reckoning(model, x_est0, U), X))
        err["raw"].append(pos_rmse(Z, X))
    rmse = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in err.items()}
    print(f"pose-meas RMSE: {rmse}; mean NEES {nees.mean():.3f}, mean NIS {nis.mean():.3f}")
    assert rmse["ekf"] < 0.5 * rmse["raw"] and rmse["ekf"] < 0.2 * rmse["dr"]
    # NEES: at each step the average over runs is chi2(n_runs*3)/n_runs if consistent
    lo, hi = chi2_band(3, n_runs)
    inside = np.mean((nees.mean(0) > lo) & (nees.mean(0) < hi))
    print(f"NEES per-step band [{lo:.2f}, {hi:.2f}], fraction inside {inside:.3f}")
    assert inside > 0.9
    # grand average: runs are independent, steps are correlated -> band with n_runs only
    assert lo < nees.mean() < hi
    # NIS: innovations are white over time too, so all n_runs*n_steps values are independent
    lo_nis, hi_nis = chi2_band(3, n_runs * n_steps)
    print(f"NIS band over all samples [{lo_nis:.3f}, {hi_nis:.3f}]")
    assert lo_nis < nis.mean() < hi_nis


# ----------------------------------------------------------------------------- (2) features
class SyntheticFeatures:
    """Smooth Phi: R^3 -> R^m, phi_k = sin(a_k . s + b_k), s = (x, y, cos yaw, sin yaw)."""

    def __init__(self, m: int, rng: np.random.Generator) -> None:
        self.A = rng.normal(0.0, 1.0, size=(m, 4)) * np.array([0.4, 0.4, 1.0, 1.0])
        self.b = rng.uniform(0, 2 * np.pi, size=m)

    def phi(self, x: np.ndarray) -> np.ndarray:
        s = np.array([x[0], x[1], np.cos(x[2]), np.sin(x[2])])
        return np.sin(self.A @ s + self.b)

    def jac(self, x: np.ndarray) -> np.ndarray:
        s = np.array([x[0], x[1], np.cos(x[2]), np.sin(x[2])])
        ds = np.array([[1, 0, 0], [0, 1, 0], [0, 0, -np.sin(x[2])], [0, 0, np.cos(x[2])]])
        return np.cos(self.A @ s + self.b)[:, None] * (self.A @ ds)


def test_feature_measurements_beat_dead_reckoning() -> None:
    rng = np.random.default_rng(1)
    model, feats, sigma = UnicycleModel(DT), SyntheticFeatures(16, rng), 0.05
    meas = FunctionMeasurement(feats.phi, feats.jac, sigma**2 * np.eye(16))
    n_runs, n_steps = 10, 200
    err_ekf, err_dr, nees, n_rejected = [], [], [], 0
    for _ in range(n_runs):
        x0 = np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)])
        x_est0 = x0 + np.linalg.cholesky(P0) @ rng.standard_normal(3)
        U = controls(n_steps, rng)
        X = simulate(model, x0, U, Q_TRUE, rng)
        Z = np.array([feats.phi(x) for x in X]) + sigma * rng.standard_normal((n_steps, 16))
        est, results, ekf = [], [], PoseEKF(model, Q_TRUE, x_est0, P0)
        for u, z, x in zip(U, Z, X):
            ekf.predict(u)
            results.append(ekf.update(z, meas))
            est.append(ekf.x.copy())
            nees.append(ekf.nees(x))
        n_rejected += sum(not r.accepted for r in results)
        err_ekf.append(pos_rmse(np.array(est), X))
        err_dr.append(pos_rmse(dead_reckoning(model, x_est0, U), X))
    rmse_ekf, rmse_dr = np.sqrt(np.mean(np.square(err_ekf))), np.sqrt(np.mean(np.square(err_dr)))
    print(f"feature EKF RMSE {rmse_ekf:.4f} vs DR {rmse_dr:.4f}; mean NEES {np.mean(nees):.3f}, "
          f"rejected {n_rejected}/{n_runs * n_steps}")
    assert rmse_ekf < 0.2 * rmse_dr
    assert 1.5 < np.mean(nees) < 6.0  # EKF linearization: loose consistency only
    assert n_rejected < 0.02 * n_runs * n_steps


# ----------------------------------------------------------------------------- (3) gating
def test_gate_rejects_outlier_and_keeps_state() -> None:
    model, meas = UnicycleModel(DT), PoseMeasurement(R_POSE)
    ekf = PoseEKF(model, Q_TRUE, [1.0, 2.0, 0.3], P0)
    ekf.predict([1.0, 0.1])
    x, P = ekf.x.copy(), ekf.P.copy()
    res = ekf.update(x + np.array([50.0, -40.0, 0.0]), meas)
    assert not res.accepted and res.nis > res.threshold and res.dim_z == 3
    np.testing.assert_array_equal(ekf.x, x)
    np.testing.assert_array_equal(ekf.P, P)
    # a typical measurement passes, and its NIS is y^T S^-1 y
    z = x + np.array([0.2, -0.1, 0.05])
    S = P + R_POSE
    y = pose_residual(z, x)
    res = ekf.update(z, meas)
    assert res.accepted and res.nis == pytest.approx(y @ np.linalg.solve(S, y))
    assert not np.allclose(ekf.x, x) and np.trace(ekf.P) < np.trace(P)
    np.testing.assert_array_equal(ekf.P, ekf.P.T)
    # gating disabled: the outlier is used
    ekf = PoseEKF(model, Q_TRUE, x, P, gate_probability=None)
    res = ekf.update(x + np.array([50.0, -40.0, 0.0]), meas)
    assert res.accepted and res.threshold == np.inf and ekf.x[0] > x[0] + 1.0


def test_gate_uses_the_models_gate_R_and_the_update_its_R() -> None:
    """A model that inflates R (e.g. for an unfamiliar image) but gates with ``gate_R``: an
    outlier the gate rejects stays rejected, however large R; an accepted measurement is
    weighted by R."""
    model = UnicycleModel(DT)
    big = PoseMeasurement(100.0 * R_POSE)
    ekf = PoseEKF(model, Q_TRUE, [1.0, 2.0, 0.3], P0)
    x, P = ekf.x.copy(), ekf.P.copy()
    outlier = x + np.array([3.0, -2.0, 0.0])
    assert ekf.update(outlier, big).accepted  # the inflated R alone lets it in
    ekf = PoseEKF(model, Q_TRUE, x, P)
    big.gate_R = lambda x: R_POSE
    res = ekf.update(outlier, big)
    assert not res.accepted
    np.testing.assert_array_equal(ekf.x, x)
    z = x + np.array([0.05, -0.02, 0.01])
    res = ekf.update(z, big)
    y = pose_residual(z, x)
    assert res.accepted and res.nis == pytest.approx(y @ np.linalg.solve(P + R_POSE, y))
    K = P @ np.linalg.inv(P + 100.0 * R_POSE)
    np.testing.assert_allclose(ekf.x, x + K @ y, atol=1e-12)


def test_gate_false_alarm_rate_matches_probability() -> None:
    rng = np.random.default_rng(2)
    meas = PoseMeasurement(R_POSE)
    ekf = PoseEKF(UnicycleModel(DT), Q_TRUE, [0.0, 0.0, 0.0], P0, gate_probability=0.9)
    S = P0 + R_POSE
    Z = rng.multivariate_normal(np.zeros(3), S, size=2000)
    rejected = 0
    for z in Z:
        rejected += not ekf.update(z, meas).accepted
        ekf.x, ekf.P = np.zeros(3), P0.copy()  # reset: same prior for every draw
    assert rejected / len(Z) == pytest.approx(0.1, abs=0.02)  # 3 sd of the rate


# ----------------------------------------------------------------------------- (4) wrapping
def test_heading_wraps_without_jumps() -> None:
    rng = np.random.default_rng(3)
    model = UnicycleModel(DT)
    n = 400  # w = 1 rad/s for 40 s: the yaw crosses +-pi about six times
    U = np.tile([1.0, 1.0], (n, 1))
    X = simulate(model, np.array([0.0, 0.0, 3.0]), U, Q_TRUE, rng)
    Z = X + rng.multivariate_normal(np.zeros(3), R_POSE, size=n)
    Z[:, 2] = wrap_angle(Z[:, 2])
    est, results = run_filter(model, X[0], U, Z, PoseMeasurement(R_POSE))
    yaw_err = wrap_angle(est[:, 2] - X[:, 2])
    assert np.sum(np.abs(np.diff(X[:, 2])) > np.pi) >= 5
    assert np.all(est[:, 2] > -np.pi) and np.all(est[:, 2] <= np.pi)
    n_rejected = sum(not r.accepted for r in results)  # gate false alarms only (0.3 % expected)
    print(f"wrap test: max |yaw error| {np.max(np.abs(yaw_err)):.4f}, rejected {n_rejected}/{n}")
    assert np.max(np.abs(yaw_err)) < 0.15 and n_rejected <= 0.02 * n
    # negative control: a plain-subtraction residual makes the estimate jump at the crossings
    naive = FunctionMeasurement(lambda x: x, lambda x: np.eye(3), R_POSE)
    est_naive, _ = run_filter(model, X[0], U, Z, naive, gate_probability=None)
    naive_err = np.max(np.abs(wrap_angle(est_naive[:, 2] - X[:, 2])))
    print(f"wrap test, unwrapped residual: max |yaw error| {naive_err:.3f}")
    assert naive_err > 1.0


def test_update_across_pi_moves_the_short_way() -> None:
    ekf = PoseEKF(UnicycleModel(DT), Q_TRUE, [0.0, 0.0, np.pi - 0.01], P0)
    res = ekf.update([0.0, 0.0, -np.pi + 0.01], PoseMeasurement(R_POSE))
    assert res.accepted and res.nis < 0.1
    assert abs(wrap_angle(ekf.x[2] - np.pi)) < 0.01


# ----------------------------------------------------------------------------- (5) bad inputs
def test_bad_inputs_raise() -> None:
    model, meas = UnicycleModel(DT), PoseMeasurement(R_POSE)
    ekf = PoseEKF(model, Q_TRUE, [0.0, 0.0, 0.0], P0)
    with pytest.raises(ValueError, match="NaN or inf"):
        ekf.update([0.0, np.nan, 0.0], meas)
    with pytest.raises(ValueError, match="NaN or inf"):
        ekf.update([0.0, np.inf, 0.0], meas)
    with pytest.raises(ValueError, match=r"shape \(2,\).*\(3,\)"):
        ekf.update([0.0, 0.0], meas)
    with pytest.raises(ValueError, match="symmetric"):
        PoseMeasurement(R_POSE + np.triu(np.ones((3, 3)), 1))
    with pytest.raises(ValueError, match="positive definite"):
        PoseMeasurement(np.diag([1.0, 0.0, 1.0]))
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        PoseMeasurement(np.eye(2))
    with pytest.raises(ValueError, match="positive definite"):
        ekf.update(np.zeros(2), FunctionMeasurement(lambda x: x[:2], lambda x: np.eye(3)[:2],
                                                    lambda x: -np.eye(2)))
    with pytest.raises(ValueError, match=r"H\(x\) must have shape \(2, 3\)"):
        ekf.update(np.zeros(2), FunctionMeasurement(lambda x: x[:2], lambda x: np.eye(3), np.eye(2)))
    with pytest.raises(ValueError, match=r"R must have shape \(2, 2\)"):
        ekf.update(np.zeros(2), FunctionMeasurement(lambda x: x[:2], lambda x: np.eye(3)[:2],
                                                    lambda x: np.eye(3)))
    with pytest.raises(ValueError, match="x0"):
        PoseEKF(model, Q_TRUE, [0.0, 0.0], P0)
    with pytest.raises(ValueError, match="P0"):
        PoseEKF(model, Q_TRUE, [0.0, 0.0, 0.0], -P0)
    with pytest.raises(ValueError, match="Q must have shape"):
        PoseEKF(model, np.eye(2), [0.0, 0.0, 0.0], P0)
    with pytest.raises(ValueError, match="gate_probability"):
        PoseEKF(model, Q_TRUE, [0.0, 0.0, 0.0], P0, gate_probability=1.5)
    with pytest.raises(ValueError, match="u must have shape"):
        ekf.predict([1.0])
    with pytest.raises(ValueError, match=r"Q\(x, u\)"):
        PoseEKF(model, lambda x, u: np.eye(2), [0.0, 0.0, 0.0], P0).predict([1.0, 0.0])
    # nothing above changed the filter
    np.testing.assert_array_equal(ekf.x, np.zeros(3))


# ----------------------------------------------------------------------------- (6) Jacobians, Q
def test_jacobians_match_finite_differences() -> None:
    rng = np.random.default_rng(4)
    feats, model = SyntheticFeatures(16, rng), UnicycleModel(DT)
    for _ in range(5):
        x = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        np.testing.assert_allclose(feats.jac(x), numerical_jacobian(feats.phi, x), atol=1e-8)
        pose = PoseMeasurement(R_POSE)
        np.testing.assert_allclose(pose.H(x), numerical_jacobian(pose.h, x, residual=pose_residual),
                                   atol=1e-8)
        u = np.array([rng.uniform(0, 2), rng.uniform(-1, 1)])
        np.testing.assert_allclose(model.jacobian_pose(x, u),
                                   numerical_jacobian(lambda p, u=u: model.predict(p, u), x,
                                                      residual=pose_residual), atol=1e-7)
    # the pose Jacobian stays correct right at the +-pi seam with the wrapped residual
    x = np.array([0.0, 0.0, np.pi])
    np.testing.assert_allclose(numerical_jacobian(lambda p: p, x, residual=pose_residual), np.eye(3))


def test_callable_Q_from_control_noise() -> None:
    model = UnicycleModel(DT)
    M, Q0 = np.diag([0.05, 0.02]) ** 2, 1e-6 * np.eye(3)
    Q = control_noise_Q(model, M, Q0)
    x, u = np.array([1.0, -1.0, 2.5]), np.array([1.2, 0.4])
    ekf_fn = PoseEKF(model, Q, x, P0)
    ekf_fn.predict(u)
    F_x, F_u = model.jacobian_pose(x, u), model.jacobian_control(x, u)
    expected_P = F_x @ P0 @ F_x.T + F_u @ M @ F_u.T + Q0
    np.testing.assert_allclose(ekf_fn.P, expected_P, rtol=1e-12)
    np.testing.assert_allclose(ekf_fn.x, model.predict(x, u))
    ekf_fixed = PoseEKF(model, Q(x, u), x, P0)
    ekf_fixed.predict(u)
    np.testing.assert_allclose(ekf_fixed.P, ekf_fn.P)


def test_chi2_band() -> None:
    lo, hi = chi2_band(3, 50)
    assert lo < 3.0 < hi and (lo, hi) == pytest.approx((2.360, 3.716), abs=1e-3)  # chi2(150) quantiles / 50
    with pytest.raises(ValueError):
        chi2_band(0, 10)


def test_nan_prediction_is_out_of_domain_not_a_crash() -> None:
    from localization.filtering.ekf import OutOfDomainError

    ekf = PoseEKF(UnicycleModel(DT), Q_TRUE, np.zeros(3), P0)
    nowhere = FunctionMeasurement(lambda x: np.full(3, np.nan), lambda x: np.eye(3), R_POSE)
    with pytest.raises(OutOfDomainError, match="no prediction"):
        ekf.update(np.zeros(3), nowhere)
    no_jacobian = FunctionMeasurement(lambda x: x, lambda x: np.full((3, 3), np.nan), R_POSE)
    with pytest.raises(OutOfDomainError, match="no Jacobian"):
        ekf.update(np.zeros(3), no_jacobian)
    assert issubclass(OutOfDomainError, ValueError)
