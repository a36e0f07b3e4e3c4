"""Closed-loop tracking on a 60 m city (nine times the default area) with a small localizer
beats dead reckoning.

City 54 (never used to choose anything) at ``city_size=60``, 32 x 32 perspective images,
PixelPCA(16), motion noise 0.1. The localizer is small: it covers only the first DRIVE steps
of the route (about 35 m of the 644 m loop through all 100 intersections), learned from
N_DRIVES drives there (``collect_dataset(mode="route")``, each with its own motion noise), its
noise and consistency from two more (:func:`fit_city_noise`, no calibration on the belief). The
run drives STEPS steps from the route's start on the belief ("representation" model); dead
reckoning integrates the same commanded controls from the true start pose.

Measured when the bounds were set (22 s with another benchmark on the 2 cores): belief RMSE
0.246 m against dead reckoning's 6.40 m (ratio 0.038), largest error 0.62 m, final error
0.53 m against 15.3 m, heading RMSE 0.094 rad, 66 % of the measurements accepted, mean NEES
18.6 (not asserted: the consistency comes from one 300-step drive, no belief calibration).
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from envs.datasets import collect_dataset
from localization.localizer import AppearanceLocalizer, city_info
from localization.workflows.tracking import fit_city_noise, track_metrics, track_route

from ..conftest import ignore_gse_warnings

CITY, DRIVE, N_DRIVES, STEPS = 54, 600, 4, 400
RMSE_BOUND = 0.5  # m; measured 0.246
RATIO_BOUND = 0.2  # belief RMSE / dead-reckoning RMSE; measured 0.038


@pytest.fixture(scope="module")
def run() -> dict[str, float]:
    env = gym.make("AppearanceNav-v0", scene_seed=CITY, city_size=60.0, image_size=(32, 32),
                   motion_noise=0.1)
    parts = [collect_dataset(env, DRIVE, "route", seed=s, progress=False)
             for s in range(N_DRIVES)]
    # the drives leave the same start pose the same way: their first frames are identical
    images = np.concatenate([p[0][10:] for p in parts])
    poses = np.concatenate([p[1][10:] for p in parts])
    with warnings.catch_warnings():
        ignore_gse_warnings()
        loc = AppearanceLocalizer(features_params={"n_components": 16}, noise_folds=0)
        loc.fit(images, poses, camera="perspective", city=city_info(env))
        fit_city_noise(env, loc, "route", n_drive=DRIVE // 2, seed=10,
                       calibrate_on_belief=False, measurements=("representation",),
                       progress=False)
        out = track_metrics(track_route(env, loc, "representation", STEPS, seed=7))
    env.close()
    return out


def test_belief_beats_dead_reckoning_on_a_60m_city(run):
    assert run["steps"] == STEPS
    assert run["rmse"] < RMSE_BOUND, run
    assert run["rmse"] < RATIO_BOUND * run["rmse_dead_reckoning"], run
    assert run["accepted"] > 0.5, run
    assert np.isfinite(run["nees_mean"])
