"""The inverse of Phi*: Gauss-Newton from psi*(w) on the whitened feature residual."""

from __future__ import annotations

import numpy as np
import pytest

from localization.geometry import wrap_angle
from localization.gse.inverse import feature_whitener, refine_poses, residual_whitener, verify_poses
from localization.gse.regressor import GSERegressor
from localization.synthetic import regression_manifold

NOISE = 0.02  # feature noise of the test images (per component)


@pytest.fixture(scope="module")
def pose3():
    """GSE on 3000 noise-free samples of a 3-DoF manifold (x, y, periodic yaw); 300 test
    images with Gaussian feature noise."""
    W, T, _ = regression_manifold(3000, dim_theta=3, seed=0)
    Wt, Tt, _ = regression_manifold(300, dim_theta=3, seed=1)
    Wt = Wt + NOISE * np.random.default_rng(2).standard_normal(Wt.shape)
    return Wt, Tt, GSERegressor(n_neighbors=20, periodic=(2,)).fit(W, T)


def cost(reg, W, theta, L):
    return np.sum(((W - reg.predict_features(theta)) @ L.T) ** 2, axis=1)


def errors(theta, T):
    return np.hypot(*(theta[:, :2] - T[:, :2]).T), np.abs(wrap_angle(theta[:, 2] - T[:, 2]))


def test_refinement_lowers_every_cost_and_the_error(pose3):
    W, T, reg = pose3
    L = feature_whitener(NOISE ** 2 * np.eye(W.shape[1]))
    theta0 = reg.predict(W)
    theta = refine_poses(reg, W, theta0, L, n_iter=3)
    before, after = cost(reg, W, theta0, L), cost(reg, W, theta, L)
    assert np.all(after <= before) and np.mean(after < before) > 0.5
    assert np.all(np.abs(theta[:, 2]) <= np.pi)
    pos0, yaw0 = errors(theta0, T)
    pos, yaw = errors(theta, T)
    # measured 2026-11-26: median position error 0.0057 -> 0.0029, heading 0.033 -> 0.016 rad
    # (the cost fell on 299 of 300 images)
    assert np.median(pos) < 0.8 * np.median(pos0) and np.median(yaw) < np.median(yaw0)


def test_no_steps_and_rows_out_of_domain_keep_their_start(pose3):
    W, _, reg = pose3
    L = np.eye(W.shape[1]) / NOISE
    theta0 = reg.predict(W[:5])
    np.testing.assert_array_equal(refine_poses(reg, W[:5], theta0, L, n_iter=0), theta0)
    theta0[1] = np.nan
    out = refine_poses(reg, W[:5], theta0, L)
    assert np.all(np.isnan(out[1])) and np.all(np.isfinite(np.delete(out, 1, axis=0)))


def test_whitener_whitens_and_bad_inputs_are_named(pose3):
    W, _, reg = pose3
    R = np.cov(np.random.default_rng(0).standard_normal((500, 4)), rowvar=False)
    L = feature_whitener(R)
    np.testing.assert_allclose(L @ R @ L.T, np.eye(4), atol=1e-6)
    with pytest.raises(ValueError, match="cov must be a symmetric"):
        feature_whitener(np.ones((3, 4)))
    with pytest.raises(ValueError, match="cov must be positive semi-definite"):
        feature_whitener(-np.eye(3))
    with pytest.raises(ValueError, match="W .n, m., theta0 .n, d. and whitener"):
        refine_poses(reg, W[:3], reg.predict(W[:2]), np.eye(W.shape[1]))
    with pytest.raises(ValueError, match="n_iter"):
        refine_poses(reg, W[:2], reg.predict(W[:2]), np.eye(W.shape[1]), n_iter=-1)


def test_verification_replaces_gross_errors_and_keeps_good_poses(pose3):
    """psi* swapped for another image's on a third of the rows: the retrieved
    training poses explain those images better and replace them; psi* where it is right
    (a candidate cannot be 3x better than a pose that explains w to the noise) stays."""
    W, T, reg = pose3
    L = feature_whitener(NOISE ** 2 * np.eye(W.shape[1]))
    theta0 = reg.predict(W)
    wrong = theta0.copy()
    wrong[::3] = np.roll(theta0, len(W) // 2, axis=0)[::3]  # a gross error: another place
    theta, switched = verify_poses(reg, W, wrong, L, n_candidates=10, margin=3.0)
    moved = np.zeros(len(W), dtype=bool)
    moved[::3] = True
    assert np.mean(switched[moved]) > 0.95 and np.mean(switched[~moved]) < 0.1
    pos, yaw = errors(theta[moved], T[moved])
    pos_wrong, _ = errors(wrong[moved], T[moved])
    # measured 2026-11-30: median position error 0.45 -> 0.028 (a training neighbour's pose,
    # so at the sample's spacing, not psi*'s 0.006)
    assert np.median(pos) < 0.2 * np.median(pos_wrong) and np.median(yaw) < 0.2
    np.testing.assert_array_equal(theta[~switched], wrong[~switched])
    assert np.all(cost(reg, W[switched], theta[switched], L)
                  < cost(reg, W[switched], wrong[switched], L) / 3.0)


def test_verification_keeps_rows_out_of_domain_and_names_bad_inputs(pose3):
    W, _, reg = pose3
    L = np.eye(W.shape[1]) / NOISE
    theta0 = reg.predict(W[:5])
    theta0[2] = np.nan
    theta, switched = verify_poses(reg, W[:5], theta0, L)
    assert np.all(np.isnan(theta[2])) and not switched[2]
    same, none = verify_poses(reg, W[:5], theta0, L, margin=1e12)
    np.testing.assert_array_equal(same, theta0)
    assert not none.any()
    with pytest.raises(ValueError, match="W .n, m., theta0 .n, d. and whitener"):
        verify_poses(reg, W[:3], reg.predict(W[:2]), L)
    with pytest.raises(ValueError, match="n_candidates"):
        verify_poses(reg, W[:2], reg.predict(W[:2]), L, n_candidates=0)
    with pytest.raises(ValueError, match="margin"):
        verify_poses(reg, W[:2], reg.predict(W[:2]), L, margin=0.5)


def test_residual_whitener_whitens_the_residuals_about_phi(pose3):
    """L of the residuals W - Phi*(Theta) makes their covariance the identity; rows whose
    pose is out of the domain are left out, and too few finite rows or shapes that disagree
    are named."""
    W, T, reg = pose3
    Theta = T.copy()
    Theta[0] = np.nan
    L = residual_whitener(reg, W, Theta)
    E = (W - reg.predict_features(T))[1:]
    np.testing.assert_allclose(np.cov((E @ L.T).T), np.eye(W.shape[1]), atol=1e-6)
    with pytest.raises(ValueError, match="W .n, m. and Theta .n, d. must have the same rows"):
        residual_whitener(reg, W[:5], T[:4])
    with pytest.raises(ValueError, match="more than m = .* finite residuals"):
        residual_whitener(reg, W[:3], T[:3])
