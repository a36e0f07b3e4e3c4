"""AppearanceLocalizer: fit/predict, the heading cut, noise models, save/load, clear errors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from envs.motion_model import wrap_angle
from localization.filtering.ekf import numerical_jacobian
from localization.geometry import pose_residual
from localization.localizer import MEASUREMENTS, AppearanceLocalizer, sparsest_heading

from .conftest import finite, ignore_gse_warnings


def test_predict_near_the_truth(localizer, lane_data):
    images, poses = lane_data
    pred = localizer.predict(images)
    ok = np.all(np.isfinite(pred), axis=1)
    assert ok.mean() > 0.9
    err = np.hypot(*(pred[ok, :2] - poses[ok, :2]).T)
    yaw = np.abs(wrap_angle(pred[ok, 2] - poses[ok, 2]))
    # 700 images of 32 x 32 for a 100 m loop: coarse, but on the right street
    assert np.median(err) < 0.6 and np.median(yaw) < 0.05


def test_refined_predict_explains_the_features_better(localizer, lane_data):
    import copy

    images, _ = lane_data
    W = localizer.transform(images[:60])
    psi = localizer.predict(images[:60])
    np.testing.assert_array_equal(localizer.predict(images[:60], refine=0), psi)
    refined = localizer.predict(images[:60], refine=3)
    assert np.array_equal(np.isfinite(refined), np.isfinite(psi))
    L, reg = localizer.feature_whitener(), localizer.regressor_

    def cost(poses):
        return np.sum(((W - reg.predict_features(localizer.to_model(poses))) @ L.T) ** 2, axis=1)

    ok = np.all(np.isfinite(psi), axis=1)
    assert np.all(cost(refined[ok]) <= cost(psi[ok]))
    with pytest.raises(ValueError, match="refine"):
        localizer.predict(images[:2], refine=-1)
    quiet = copy.deepcopy(localizer)
    quiet.noise_ = {}
    with pytest.raises(NotFittedError, match="noise"):
        quiet.predict(images[:2], refine=3)


def test_verified_predict_explains_the_switched_images_better(localizer, lane_data):
    import copy

    images, _ = lane_data
    W = localizer.transform(images[:60])
    psi = localizer.predict(images[:60])
    np.testing.assert_array_equal(localizer.predict(images[:60], verify=0), psi)
    checked = localizer.predict(images[:60], verify=10, verify_margin=3.0)
    assert np.array_equal(np.isfinite(checked), np.isfinite(psi))
    L, reg = localizer.feature_whitener(), localizer.regressor_

    def cost_of(poses, rows):
        F = reg.predict_features(localizer.to_model(poses[rows]))
        return np.sum(((W[rows] - F) @ L.T) ** 2, axis=1)

    changed = np.all(np.isfinite(psi), axis=1) & np.any(checked != psi, axis=1)
    assert changed.any()  # 12 of 60 on this coarse 32 x 32 map (2026-11-30)
    assert np.all(3.0 * cost_of(checked, changed) < cost_of(psi, changed))
    with pytest.raises(ValueError, match="verify"):
        localizer.predict(images[:2], verify=-1)
    with pytest.raises(ValueError, match="verify_margin"):
        localizer.predict(images[:2], verify=5, verify_margin=0.9)
    quiet = copy.deepcopy(localizer)
    quiet.noise_ = {}
    with pytest.raises(NotFittedError, match="noise"):
        quiet.predict(images[:2], verify=5)


def test_heading_cut_is_where_no_lane_goes(localizer):
    theta = localizer._from_model(localizer.regressor_.theta_)
    gap = np.abs(wrap_angle(theta[:, 2] - localizer.yaw_cut_))
    assert np.mean(gap < 0.05) < 0.005  # almost no training heading near the cut
    assert sparsest_heading(np.r_[np.zeros(50), np.full(50, np.pi / 2)], bins=4) in \
        (-3 * np.pi / 4, -np.pi / 4)


def test_noise_models(localizer):
    for name in MEASUREMENTS:
        R = localizer.noise_[name]
        assert np.all(np.linalg.eigvalsh(R) > 0)
        assert np.all(localizer.correlation_time_[name] >= 1.0)
    Q = localizer.process_noise_body_
    assert np.all(np.linalg.eigvalsh(Q) > 0) and Q[0, 0] > Q[1, 1]  # slip along > across
    assert np.all(np.abs(localizer.control_gain_ - 1.0) < 0.15)
    x = np.array([3.0, -9.0, 0.3])
    R_pose = localizer.measurement_model("pose").R_at(x)
    R_body = localizer.noise_["pose"]
    c, s = np.cos(x[2]), np.sin(x[2])
    T = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(R_pose, T @ R_body @ T.T)


def test_representation_jacobian_matches_finite_differences(localizer, lane_data):
    model = localizer.measurement_model("representation")
    for x in lane_data[1][::60]:
        H = model.H(x)
        if not finite(H):
            continue
        Hn = numerical_jacobian(model.h, x, eps=1e-4)
        assert np.linalg.norm(H - Hn) < 0.1 * np.linalg.norm(Hn)


def test_measurements_and_residual(localizer, lane_data):
    w = localizer.transform(lane_data[0][:1])[0]
    assert localizer.measure(w, "features").shape == w.shape
    assert localizer.measure(w, "representation").shape == (3,)
    z = localizer.measure(w, "pose")
    assert np.allclose(z, localizer.predict(lane_data[0][:1])[0])
    d = pose_residual([0, 0, 3.1], [0, 0, -3.1])
    assert d[2] == pytest.approx(6.2 - 2 * np.pi)


def test_save_load_round_trip(localizer, lane_data, tmp_path):
    path = tmp_path / "loc.npz"
    localizer.save(path)
    again = AppearanceLocalizer.load(path)
    images = lane_data[0][:20]
    assert np.array_equal(localizer.predict(images), again.predict(images), equal_nan=True)
    for name in MEASUREMENTS:
        assert np.array_equal(localizer.noise_[name], again.noise_[name])
    assert np.array_equal(localizer.process_noise_body_, again.process_noise_body_)
    assert again.camera_ == "perspective" and again.image_size_ == (32, 32)
    np.testing.assert_array_equal(again.dropped_, localizer.dropped_)
    x = lane_data[1][5]
    assert np.allclose(localizer.measurement_model("representation").h(x),
                       again.measurement_model("representation").h(x))
    with np.load(path, allow_pickle=False):
        pass  # no pickled objects inside
    bad = tmp_path / "bad.npz"
    bad.write_bytes(path.read_bytes()[:500])
    with pytest.raises(ValueError, match="not a saved|corrupted"):
        AppearanceLocalizer.load(bad)


def test_load_takes_the_path_given_to_save(localizer, lane_data, tmp_path):
    """numpy's savez appends ".npz" to a name without it; load finds that file from the same
    path (a user's save("maps/city") then load("maps/city") works)."""
    localizer.save(tmp_path / "maps" / "city")
    assert (tmp_path / "maps" / "city.npz").is_file()
    again = AppearanceLocalizer.load(tmp_path / "maps" / "city")
    images = lane_data[0][:5]
    assert np.array_equal(localizer.predict(images), again.predict(images), equal_nan=True)
    with pytest.raises(FileNotFoundError, match="elsewhere"):
        AppearanceLocalizer.load(tmp_path / "elsewhere")


def test_fit_is_deterministic_and_k_fold_noise(lane_data):
    images, poses = lane_data
    a = AppearanceLocalizer(features_params={"n_components": 8}, noise_folds=2)
    b = AppearanceLocalizer(features_params={"n_components": 8}, noise_folds=2)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        a.fit(images, poses)
        b.fit(images, poses)
    assert np.array_equal(a.predict(images[:10]), b.predict(images[:10]), equal_nan=True)
    assert set(a.noise_) == set(MEASUREMENTS)
    assert all(np.all(np.linalg.eigvalsh(R) > 0) for R in a.noise_.values())
    with pytest.raises(NotFittedError, match="process noise"):
        a.process_noise(poses[0])


def test_clear_errors(localizer, lane_data):
    images, poses = lane_data
    with pytest.raises(NotFittedError):
        AppearanceLocalizer().predict(images)
    with pytest.raises(NotFittedError, match="noise"), warnings.catch_warnings():
        ignore_gse_warnings()
        AppearanceLocalizer(noise_folds=0, features_params={"n_components": 8}).fit(
            images, poses).measurement_model("pose")
    with pytest.raises(ValueError, match="32, 32"):
        localizer.predict(np.zeros((1, 48, 48, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        localizer.predict(images[:2].astype(np.float32))
    with pytest.raises(ValueError, match="unknown measurement"):
        localizer.measurement_model("lidar")
    with pytest.raises(ValueError, match="rows"):
        AppearanceLocalizer(rows=(0.6, 0.2)).fit(images, poses)
    with pytest.raises(ValueError, match="noise_folds"):
        AppearanceLocalizer(noise_folds=1).fit(images, poses)
    with pytest.raises(ValueError, match="max_dropped"):
        AppearanceLocalizer(max_dropped=1.0).fit(images, poses)
    with pytest.raises(ValueError, match="poses"):
        AppearanceLocalizer().fit(images, poses[:-1])
    with pytest.raises(ValueError, match="NaN"):
        AppearanceLocalizer().fit(images, np.full_like(poses, np.nan))
    with pytest.raises(ValueError, match="controls"):
        localizer.fit_noise(None, images[:11], poses[:11], np.zeros((5, 2)))
