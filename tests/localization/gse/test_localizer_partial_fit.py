"""AppearanceLocalizer.partial_fit: a thin delegate to GSERegressor.partial_fit."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from envs.datasets import collect_dataset
from localization.localizer import AppearanceLocalizer

from ..conftest import ignore_gse_warnings, make_env


def _fit(images: np.ndarray, poses: np.ndarray) -> AppearanceLocalizer:
    loc = AppearanceLocalizer(features_params={"n_components": 16}, noise_folds=0)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        return loc.fit(images, poses, camera="perspective")


def _errors(loc: AppearanceLocalizer, images: np.ndarray, poses: np.ndarray) -> np.ndarray:
    P = loc.predict(images)
    ok = np.isfinite(P).all(axis=1)
    assert ok.mean() > 0.9
    return np.hypot(*(P[ok, :2] - poses[ok, :2]).T)


def test_localizer_partial_fit_matches_a_refit(lane_data):
    env = make_env()
    images, poses = collect_dataset(env, 800, "lanes", seed=2, progress=False, lanes="route")
    env.close()
    grown = _fit(images[:650], poses[:650])
    cut = grown.yaw_cut_
    with warnings.catch_warnings():
        ignore_gse_warnings()
        assert grown.partial_fit(images[650:], poses[650:]) is grown
    assert len(grown.regressor_.theta_) == 800 and grown.yaw_cut_ == cut
    refit = _fit(images, poses)
    held_images, held_poses = lane_data
    e_inc, e_ref = _errors(grown, held_images, held_poses), _errors(refit, held_images,
                                                                     held_poses)
    assert np.median(e_inc) <= 1.1 * np.median(e_ref)
    # on the added images themselves (now training samples) as good as the refit
    e_inc, e_ref = (_errors(m, images[650:], poses[650:]) for m in (grown, refit))
    assert np.median(e_inc) <= 1.1 * np.median(e_ref)


def test_localizer_partial_fit_errors(localizer, lane_data):
    images, poses = lane_data
    with pytest.raises(NotFittedError, match="call fit"):
        AppearanceLocalizer().partial_fit(images[:5], poses[:5])
    n = len(localizer.regressor_.theta_)
    with pytest.raises(ValueError, match="fitted on"):
        localizer.partial_fit(np.zeros((2, 16, 16, 3), np.uint8), poses[:2])
    with pytest.raises(ValueError, match="poses"):
        localizer.partial_fit(images[:3], poses[:3, :2])
    bad = poses[:3].copy()
    bad[0, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        localizer.partial_fit(images[:3], bad)
    assert len(localizer.regressor_.theta_) == n
