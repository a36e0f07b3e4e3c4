"""fit_city_localizer names the argument to change when its noise drive is too short,
learns its noise where ``noise_env`` says, and fits one map per look of ``experience_envs``."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

from localization.workflows.tracking import fit_city_localizer

from ..conftest import make_env


def test_too_short_a_noise_drive_names_n_drive():
    env = make_env()
    try:
        with warnings.catch_warnings(), pytest.raises(ValueError, match="n_drive=60"):
            warnings.simplefilter("ignore", RuntimeWarning)
            fit_city_localizer(env, n_train=400, lanes="route", n_drive=60,
                               localizer_params={"features_params": {"n_components": 16}})
    finally:
        env.close()


def _fit(env, noise_env=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loc, _ = fit_city_localizer(env, n_train=400, lanes="route", n_drive=200,
                                    localizer_params={"features_params": {"n_components": 8}},
                                    calibrate_on_belief=False, measurements=("representation",),
                                    quality_steps=0, noise_env=noise_env)
    return loc


def test_noise_env_drives_the_noise_model_and_not_the_map():
    """A map fitted in daylight learns its measurement noise where noise_env says."""
    env, dusk = make_env(), make_env(conditions="dusk")
    try:
        plain, other = _fit(env), _fit(env, noise_env=dusk)
        assert plain.fingerprint_ == other.fingerprint_  # the same daylight map images
        assert not np.allclose(plain.noise_["representation"], other.noise_["representation"])
        other_city = gym.make("AppearanceNav-v0", scene_seed=1)
        with pytest.raises(ValueError, match="noise_env must show the same city"):
            fit_city_localizer(env, n_train=400, n_drive=200, noise_env=other_city)
        other_city.close()
    finally:
        env.close()
        dusk.close()


def test_experience_envs_give_one_map_per_look():
    """Each experience env adds a map of the same training poses in its look."""
    from envs.conditions import experience_looks
    from localization.experiences import ExperienceLocalizer

    env, night = make_env(), make_env(conditions=experience_looks(0)[2])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            loc, _ = fit_city_localizer(
                env, n_train=400, lanes="route", n_drive=200,
                localizer_params={"features_params": {"n_components": 8}},
                calibrate_on_belief=False, measurements=("representation",), quality_steps=0,
                experience_envs=[night])
        assert isinstance(loc, ExperienceLocalizer)
        assert loc.labels_ == ["0:default", "1:random:night"]
        assert loc.n_train_[0] >= 390 and loc.n_train_[1] >= 390  # 400 poses, each look
        other_city = gym.make("AppearanceNav-v0", scene_seed=1)
        with pytest.raises(ValueError, match="experience_envs must show the same city"):
            fit_city_localizer(env, n_train=400, n_drive=200, experience_envs=[other_city])
        with pytest.raises(ValueError, match="districts and experience_envs"):
            fit_city_localizer(env, n_train=400, n_drive=200, experience_envs=[night],
                               districts=(2, 1))
        other_city.close()
    finally:
        env.close()
        night.close()
