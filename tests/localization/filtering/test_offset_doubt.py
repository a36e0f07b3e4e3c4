"""DivergenceMonitor's offset test (status only): "doubtful" while the median of the recent
psi* puts the robot somewhere the belief is not (method §13.1, stop 74)."""

from __future__ import annotations

import numpy as np
import pytest

from localization.filtering.divergence import DivergenceMonitor
from tests.localization.filtering.test_divergence import FAR, NEAR, SIDEWAYS, feed


def test_offset_doubt_holds_while_the_images_agree_elsewhere():
    """psi* 1.2 m beside the belief: doubtful from the 4th such step on and for as long as it
    lasts (not once per fresh run as the drift test), never a drift (nothing to widen) nor
    lost; once psi* agrees with the belief again, the doubt goes with the median."""
    m = DivergenceMonitor(offset_doubt=0.5, drift_steps=4)
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 8, 4.0, SIDEWAYS, False)
    assert [v.doubtful for v in verdicts] == [False] * 2 + [True] * 6  # 3 of 4 off
    assert all(v.drift is None and not v.lost and v.restart is None for v in verdicts)
    assert feed(m, 1, 1.5, NEAR, False)[0].doubtful  # the median of 4: three still off
    assert not feed(m, 1, 1.5, NEAR, False)[0].doubtful


def test_offset_doubt_reads_the_median_of_scattered_psi():
    """psi* scattered 0.3-1.9 m around a place 1.4 m off the belief (a shove, tuning city
    13): no two agree within 0.5 m, the median says where the robot is."""
    m = DivergenceMonitor(offset_doubt=0.5, drift_steps=4)
    feed(m, 8, 1.5, NEAR, False)
    scattered = [np.array([dx, 1.4 + dy, 0.0]) for dx, dy in
                 ((0.3, 0.2), (-0.9, -0.4), (0.8, 1.5), (-0.2, 0.9))]
    verdicts = [feed(m, 1, 4.0, psi, False)[0] for psi in scattered]
    assert [v.doubtful for v in verdicts] == [False, False, True, True]


@pytest.mark.parametrize("psis, u", [
    ([SIDEWAYS, -SIDEWAYS], (0.5, 0.0)),  # scattered on both sides: no place agreed on
    ([np.array([0.0, 0.6, 0.0])], (0.5, 0.0)),  # 0.6 m off: within 0.5 m + 3 sigma (0.3 m)
    ([SIDEWAYS], (0.0, 0.0)),  # one view at rest: one error, however often
    ([NEAR, NEAR, NEAR, FAR], (0.5, 0.0)),  # an aliased psi* now and then: the median stays
])
def test_no_offset_doubt_without_agreement_far_enough_from_new_views(psis, u):
    m = DivergenceMonitor(offset_doubt=0.5, drift_steps=4)
    verdicts = [feed(m, 1, 4.0, psis[t % len(psis)], False, u=u)[0] for t in range(12)]
    assert not any(v.doubtful for v in verdicts)


def test_offset_doubt_is_checked():
    with pytest.raises(ValueError, match="offset_doubt"):
        DivergenceMonitor(offset_doubt=-0.5)
    assert DivergenceMonitor().offset_doubt is None  # off by default
