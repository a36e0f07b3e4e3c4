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
    assert check_settings(s, "opt", Settings) == s


def test_an_instance_is_copied_so_two_filters_do_not_share_its_state(localizer):
    """One stateful settings object given to two beliefs (or to a wrapper that makes one
    per env): each belief gets its own copy, so one's innovations never scale the other's R."""
    from localization.filtering.adaptive_noise import InnovationScale
    from localization.filtering.divergence import DivergenceMonitor
    from tests.localization.conftest import make_env

    F = make_env().unwrapped.motion_model
    scale, monitor = InnovationScale(rate=0.5), DivergenceMonitor(window=10)
    a = BeliefFilter(localizer, F, adaptive_noise=scale, detect_divergence=monitor)
    b = BeliefFilter(localizer, F, adaptive_noise=scale, detect_divergence=monitor)
    assert a.adaptive is not b.adaptive and a.adaptive is not scale
    assert a.monitor is not b.monitor and a.monitor is not monitor
    assert (a.adaptive.rate, a.monitor.window) == (0.5, 10)
    a.adaptive.record(30.0, 3, 50.0)
    assert a.adaptive.scale > 1.0
    assert b.adaptive.scale == 1.0 and scale.scale == 1.0


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
