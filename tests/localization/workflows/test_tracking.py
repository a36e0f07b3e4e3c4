"""Closed-loop tracking on a city not used to choose any default (held out).

The defaults (lanes tube, image rows, noise model, gate, recovery) were chosen on cities 0-3
(city 5 was looked at once, too); this test fits a localizer on city 7 from scratch and
drives its route on the belief: 64 x 64 perspective, motion noise 0.1, 6000 route-lane
images, noise from a 1500-step drive, 3 runs of 500 steps from different points of the
route. Measured when the bounds were set (9 runs: these 3 starts x 3 motion-noise seeds):
representation RMSE 0.05-0.23 m, ratio to dead reckoning 0.01-0.11, largest error 0.55 m,
mean NEES 2.6 (runs 0.5-9.8); "pose" RMSE 0.04-0.12 m; "features" 0.2-1.8 m (it runs, but it
is the weak model: see the README).
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401
from localization.filtering.belief import STATUSES
from localization.localizer import MEASUREMENTS
from localization.workflows.tracking import (
    fit_city_localizer,
    nees_band,
    track_metrics,
    track_route,
)

from ..conftest import ignore_gse_warnings

CITY = 7
STARTS = (0, 600, 1200)  # route path points, 5 cm apart: three different stretches
STEPS = 500
RMSE_BOUND = 0.35  # m; measured <= 0.23 (see the module docstring)
MAX_ERROR_BOUND = 1.0  # m, never lost; measured <= 0.55
RATIO_BOUND = 0.30  # belief RMSE / dead-reckoning RMSE of the same run (the bound)


@pytest.fixture(scope="module")
def city():
    env = gym.make("AppearanceNav-v0", scene_seed=CITY, motion_noise=0.1,
                   max_episode_steps=None)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        loc, _ = fit_city_localizer(env, n_train=6000, lanes="route", n_drive=1500, seed=0,
                                    measurements=("representation",))
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
        assert m["max_error"] < MAX_ERROR_BOUND, m
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
    """Not calibrated here (the fixture calibrates "representation" only, for time): they must
    run, with valid beliefs; "pose" must keep accepting its measurements."""
    env, loc = city
    run = track_route(env, loc, measurement, 200, start=STARTS[1], seed=30)
    assert np.all(np.isfinite(run.mean)) and np.all(np.isfinite(run.cov))
    assert np.all(np.linalg.eigvalsh(run.cov) > 0)
    assert set(run.status) <= set(STATUSES)  # "reverted": a restart its images did not confirm
    assert run.nis_dof == (loc.noise_["features"].shape[0] if measurement == "features" else 3)
    if measurement == "pose":
        assert np.mean(np.array(run.status) == "accepted") > 0.5


def test_closed_loop_under_sensor_noise_holds(city, runs):
    """Issue 14: the same drives (starts, seeds) under the "noise" preset (sensor noise of
    standard deviation 0.05 on every image), on the localizer fitted in today's look.
    Measured when the bounds were set (the 3 starts x seeds 20-22, 30-32, 40-42): RMSE
    0.04-0.14 m, largest error 0.90 m, mean NEES 2.1-7.5 per run, 98-100 % accepted. Targets
    (the issue's closed-loop ones): RMSE <= 2x the daylight RMSE of the same drive, mean NEES
    in the chi-square band."""
    _, loc = city
    noisy = gym.make("AppearanceNav-v0", scene_seed=CITY, motion_noise=0.1,
                     max_episode_steps=None, conditions="noise")
    metrics = [track_metrics(track_route(noisy, loc, "representation", STEPS, start=s,
                                         seed=20 + i)) for i, s in enumerate(STARTS)]
    noisy.close()
    for m, day in zip(metrics, runs):
        assert m["rmse"] < RMSE_BOUND, m
        assert m["rmse"] <= 2.0 * track_metrics(day)["rmse"], (m, track_metrics(day))
        assert m["max_error"] < MAX_ERROR_BOUND, m
        assert m["accepted"] > 0.8, m
    lo, hi = nees_band(len(metrics))
    mean = float(np.mean([m["nees_mean"] for m in metrics]))
    assert lo <= mean <= hi, (mean, lo, hi)


def test_recover_asks_a_recovery_before_every_command_and_obeys_it(city, monkeypatch):
    """``recover=True``: a Recovery sees each step's ``info`` before the pilot; where it acts,
    its action is the command; where it does not, the drive is the plain one."""
    from localization.filtering.divergence import BELIEF_STATUSES
    from localization.workflows import tracking

    seen: list[str] = []

    class Spy(tracking.Recovery):
        def act(self, yaw, info):
            seen.append(info["belief_status"])
            return np.array([0.0, 0.5], np.float32) if len(seen) == 10 else None

    monkeypatch.setattr(tracking, "Recovery", Spy)
    env, loc = city
    plain = track_route(env, loc, "representation", 30, seed=20)
    spied = track_route(env, loc, "representation", 30, seed=20, recover=True)
    assert len(seen) == 30 and set(seen) <= set(BELIEF_STATUSES)
    np.testing.assert_array_equal(spied.controls[:9], plain.controls[:9])
    np.testing.assert_array_equal(spied.controls[9], [0.0, 0.5])
