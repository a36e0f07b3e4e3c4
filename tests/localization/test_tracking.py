"""Closed-loop tracking on a city not used to choose any default (held out).

The defaults (lanes tube, image rows, noise model, gate, recovery) were chosen on cities 0-3;
this test fits a localizer on city 5 from scratch and drives its route on the belief.
Measured when the bounds were set (64 x 64 perspective, motion noise 0.05, 6000 route-lane
images, 3 runs of 500 steps): see the bounds below for the numbers and margins.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from localization.localizer import MEASUREMENTS
from localization.tracking import (
    fit_city_localizer,
    nees_band,
    track_metrics,
    track_route,
)

from .conftest import ignore_gse_warnings

CITY = 5
STARTS = (0, 600, 1200)  # route path points, 5 cm apart: three different stretches
STEPS = 500
RMSE_BOUND = 0.30  # m; measured 0.06-0.10 (see the module docstring)
RATIO_BOUND = 0.30  # belief RMSE / dead-reckoning RMSE of the same run (the bound)


@pytest.fixture(scope="module")
def city():
    env = gym.make("AppearanceNav-v0", scene_seed=CITY, motion_noise=0.05,
                   max_episode_steps=None)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        loc, _ = fit_city_localizer(env, n_train=6000, lanes="route", n_drive=800, seed=0)
    yield env, loc
    env.close()


@pytest.fixture(scope="module")
def runs(city):
    env, loc = city
    return [track_route(env, loc, "representation", STEPS, start=s, seed=20 + i)
            for i, s in enumerate(STARTS)]


def test_closed_loop_rmse_is_bounded_and_beats_dead_reckoning(runs):
    for run in runs:
        m = track_metrics(run)
        assert m["rmse"] < RMSE_BOUND, m
        assert m["ratio"] <= RATIO_BOUND, m
        assert m["final_error"] < RMSE_BOUND, m
        assert m["accepted"] > 0.8, m


def test_mean_nees_in_the_chi2_band(runs):
    """Band: each run's time-averaged NEES counts as one chi2(3) draw (steps of one run are
    strongly correlated), so the mean of 3 runs lies in chi2.ppf([.025, .975], 9) / 3 =
    [0.90, 6.34] for a consistent filter."""
    lo, hi = nees_band(len(runs))
    mean = float(np.mean([track_metrics(r)["nees_mean"] for r in runs]))
    assert lo <= mean <= hi, (mean, lo, hi)


@pytest.mark.parametrize("measurement", [m for m in MEASUREMENTS if m != "representation"])
def test_other_measurement_models_run_closed_loop(city, measurement):
    env, loc = city
    run = track_route(env, loc, measurement, 200, start=STARTS[0], seed=30)
    assert np.all(np.isfinite(run.mean)) and np.all(np.isfinite(run.cov))
    assert np.all(np.linalg.eigvalsh(run.cov) > 0)
    assert set(run.status) <= {"initial", "accepted", "gated", "out_of_domain", "relocalized"}
    assert np.mean(np.array(run.status) == "accepted") > 0.5
