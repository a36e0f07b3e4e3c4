"""``check_settings``: the one resolver of the bool-or-settings options of the belief
(``adaptive_noise``, ``measurement_bias``, ``detect_divergence``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from localization._validation import check_settings
from localization.filtering.belief import BeliefFilter


@dataclass(frozen=True)
class Settings:
    rate: float = 0.1


def test_each_kind_of_option():
    assert check_settings(False, "opt", Settings) is None
    assert check_settings(np.False_, "opt", Settings) is None
    assert check_settings(True, "opt", Settings) == Settings()
    assert check_settings({"rate": 0.3}, "opt", Settings) == Settings(rate=0.3)
    s = Settings(rate=0.2)
    assert check_settings(s, "opt", Settings) is s


@pytest.mark.parametrize("option, match", [
    ("on", "opt must be a bool, a dict of Settings settings or a Settings, got str"),
    (None, "got NoneType"),
    ({"window": 3}, "opt: .*window"),
])
def test_bad_options_name_the_argument(option, match):
    with pytest.raises(TypeError, match=match):
        check_settings(option, "opt", Settings)


@pytest.mark.parametrize("name", ["adaptive_noise", "measurement_bias", "detect_divergence"])
def test_the_beliefs_options_name_themselves(localizer, name):
    from tests.localization.conftest import make_env

    F = make_env().unwrapped.motion_model
    with pytest.raises(TypeError, match=f"^{name}"):
        BeliefFilter(localizer, F, **{name: "yes"})
    with pytest.raises(TypeError, match=f"^{name}: .*nonsense"):
        BeliefFilter(localizer, F, **{name: {"nonsense": 1}})
