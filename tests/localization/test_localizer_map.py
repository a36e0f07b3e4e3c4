"""A localizer that knows its map: its city, its training images' fingerprint, the refusal to
run in another city, format-2 files, and fit_city_localizer's quality report and warning."""

from __future__ import annotations

import io
import json
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

from envs.datasets import collect_dataset
from localization.localizer import (
    AppearanceLocalizer,
    OtherCityError,
    city_info,
    images_fingerprint,
)
from localization.workflows.quality import (
    LocalizerQualityWarning,
    quality_problems,
    quality_report,
)
from localization.workflows.tracking import (
    fit_city_localizer,
    track_metrics,
    track_route,
)
from tests.localization.conftest import SIZE, ignore_gse_warnings, make_env


@pytest.fixture(scope="module")
def envs01():
    env0 = make_env()
    env1 = gym.make("AppearanceNav-v0", scene_seed=1, image_size=SIZE, motion_noise=0.05)
    yield env0, env1
    env0.close()
    env1.close()


@pytest.fixture(scope="module")
def city_localizer(envs01, drive):
    """Fitted on city 0 with its city (700 lane images, noise from the shared drive)."""
    env0, _ = envs01
    images, poses = collect_dataset(env0, 700, "lanes", seed=0, progress=False, lanes="route")
    loc = AppearanceLocalizer(features_params={"n_components": 16}, noise_folds=0)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        loc.fit(images, poses, camera="perspective", city=city_info(env0))
    loc.fit_noise(env0.unwrapped.motion_model, *drive)
    return loc, images


def test_city_info_names_the_city(envs01):
    env0, env1 = envs01
    a, b = city_info(env0), city_info(env1)
    assert a["scene_seed"] == 0 and b["scene_seed"] == 1
    assert a["layout"] != b["layout"]
    again = make_env()
    assert city_info(env0.unwrapped.city) == a == city_info(again)  # deterministic
    again.close()
    assert json.loads(json.dumps(a)) == a
    with pytest.raises(TypeError, match="AppearanceNav env"):
        city_info(object())


def test_localizer_refuses_another_city_unless_told(envs01, city_localizer):
    env0, env1 = envs01
    loc, _ = city_localizer
    loc.check_city(city_info(env0))  # its own city
    with pytest.raises(OtherCityError, match="allow_other_city=True") as err:
        loc.check_city(city_info(env1))
    assert isinstance(err.value, ValueError)
    assert "scene_seed=0" in str(err.value) and "scene_seed=1" in str(err.value)
    loc.check_city(city_info(env1), allow_other_city=True)
    loc.check_city(None)  # the env's city unknown: nothing to compare
    with pytest.raises(OtherCityError, match="--allow-other-city"):
        track_route(env1, loc, "pose", 5)
    run = track_route(env1, loc, "pose", 5, allow_other_city=True)
    assert len(run.true) == 6
    with pytest.raises(TypeError, match="allow_other_city"):
        loc.check_city(city_info(env1), allow_other_city="yes")


def test_fit_validates_the_city(lane_data):
    with pytest.raises(TypeError, match="city must be a dict"):
        AppearanceLocalizer().fit(*lane_data, city="city 0")
    with pytest.raises(TypeError, match=r"city\['x'\]"):
        AppearanceLocalizer().fit(*lane_data, city={"x": object()})


def test_fingerprint_is_stable_and_names_the_images(tmp_path, envs01, city_localizer):
    _, env1 = envs01
    loc, images = city_localizer
    assert isinstance(loc.fingerprint_, str) and len(loc.fingerprint_) == 64
    assert images_fingerprint(images.copy()) == loc.fingerprint_  # the same images: the same
    loc.quality_ = {"rmse": 0.25, "ratio": math.nan}
    loc.save(tmp_path / "loc.npz")
    again = AppearanceLocalizer.load(tmp_path / "loc.npz")
    assert again.fingerprint_ == loc.fingerprint_
    assert again.city_ == loc.city_
    assert again.quality_["rmse"] == 0.25 and math.isnan(again.quality_["ratio"])
    with pytest.raises(OtherCityError):
        again.check_city(city_info(env1))
    other, poses = collect_dataset(env1, 700, "lanes", seed=0, progress=False, lanes="route")
    refit = AppearanceLocalizer(features_params={"n_components": 16}, noise_folds=0)
    with warnings.catch_warnings():
        ignore_gse_warnings()
        refit.fit(other, poses)
    assert refit.fingerprint_ != loc.fingerprint_
    assert refit.city_ is None  # fitted without city=: unknown, never refused
    refit.check_city(city_info(envs01[0]))


def _as_format_2(path, out):
    """Rewrite a saved localizer as the format-2 code wrote it: no city, fingerprint or
    quality arrays."""
    with np.load(path, allow_pickle=False) as f:
        data = {k: f[k] for k in f.files if not k.startswith("quality/")}
    settings = json.loads(str(data.pop("settings")))
    settings["format"] = "appearance-nav-localizer/2"
    del settings["city"], settings["fingerprint"]
    np.savez_compressed(out, settings=np.array(json.dumps(settings)), **data)


def test_format_2_files_still_load_with_an_unknown_city(tmp_path, envs01, city_localizer,
                                                        lane_data):
    loc, _ = city_localizer
    loc.save(tmp_path / "new.npz")
    _as_format_2(tmp_path / "new.npz", tmp_path / "old.npz")
    old = AppearanceLocalizer.load(tmp_path / "old.npz")
    assert old.city_ is None and old.fingerprint_ is None and old.quality_ == {}
    np.testing.assert_array_equal(old.predict(lane_data[0][:20]), loc.predict(lane_data[0][:20]))
    old.check_city(city_info(envs01[1]))  # unknown city: not checked
    buf = io.BytesIO()
    np.savez(buf, settings=np.array(json.dumps({"format": "appearance-nav-localizer/9"})))
    (tmp_path / "future.npz").write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="unknown format"):
        AppearanceLocalizer.load(tmp_path / "future.npz")


def test_quality_report_keys_and_problems():
    metrics = {"steps": 400, "rmse": 0.4, "rmse_dead_reckoning": 1.0, "ratio": 0.4,
               "accepted": 0.99, "nees_mean": 3.1, "max_error": 1.1, "yaw_rmse": 0.01}
    q = quality_report(metrics, {"pose": np.array([2.0, 1.0, 1.0]),
                                 "features": np.array([100.0, 3.0, 1.0])})
    assert set(q) >= {"steps", "rmse", "rmse_dead_reckoning", "ratio", "accepted",
                      "nees_mean", "alpha_pose_along", "alpha_features_heading", "alpha_max",
                      "alpha_cap", "alpha_at_cap"}
    assert all(isinstance(v, float) and math.isfinite(v) for v in q.values())
    assert q["alpha_at_cap"] == 1.0
    problems = quality_problems(q)
    assert len(problems) == 1 and "'features'" in problems[0] and "along" in problems[0]
    assert quality_problems({**q, "ratio": 1.8, "alpha_features_along": 3.0})[0].startswith(
        "its belief is worse than dead reckoning")
    assert quality_problems({**q, "alpha_features_along": 3.0}) == []
    skipped = quality_report(None, {})
    assert math.isnan(skipped["rmse"]) and quality_problems(skipped) == []


def _fit(n_train: int):
    env = make_env(max_episode_steps=None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ignore_gse_warnings()
        loc, seconds = fit_city_localizer(
            env, n_train=n_train, lanes="route", n_drive=400, seed=0,
            measurements=("representation",),
            localizer_params={"features_params": {"n_components": 16}})
    env.close()
    return loc, seconds, [w for w in caught if issubclass(w.category, LocalizerQualityWarning)]


def test_fit_city_localizer_warns_when_under_trained(envs01):
    # measured: 150 images -> belief RMSE 3.3 m, 4.6x dead reckoning's with the BLAS / torch
    # threads of the machine and 2.5x with one thread (how `make test` runs). 200 images read
    # 4.64 m, 1.3x, but 2.13 m, 0.38x on one thread: a fit this thin is chaotic in the
    # summation order, so the case is chosen to be worse than dead reckoning both ways.
    # (300 images were the case before the walls were smooth: 4.18 vs 1.04 m.)
    loc, seconds, warned = _fit(150)
    assert loc.quality_["ratio"] > 1.0
    assert len(warned) == 1
    message = str(warned[0].message)
    assert "worse than dead reckoning" in message
    assert f"{loc.quality_['rmse']:.2f} m" in message
    assert loc.city_ == city_info(envs01[0]) and "quality" in seconds
    assert all(math.isfinite(v) for v in loc.quality_.values())
    assert loc.quality_["steps"] == 400.0


def test_fit_city_localizer_quality_of_a_sound_fit(envs01):
    # measured: 800 images -> ratio 0.42, factors <= 11.4: no warning
    loc, _, warned = _fit(800)
    assert warned == []
    q = loc.quality_
    assert q["ratio"] < 1.0 and q["alpha_at_cap"] == 0.0
    assert all(math.isfinite(v) for v in q.values())
    # the report is the held-out drive's scores (seed + 3) with the final calibration
    env = make_env(max_episode_steps=None)
    run = track_route(env, loc, "representation", 400, seed=3)
    env.close()
    assert track_metrics(run)["rmse"] == pytest.approx(q["rmse"])
    with pytest.raises(OtherCityError):
        track_route(envs01[1], loc, "representation", 5)
