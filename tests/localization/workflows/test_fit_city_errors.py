"""fit_city_localizer names the argument to change when its noise drive is too short."""

from __future__ import annotations

import warnings

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
