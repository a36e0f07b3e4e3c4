"""Recovery: what a pilot does before it steers on the belief (back off after a contact, look
around while lost), alone and in the closed-loop tracking drives (``recover=True``)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.recovery import Recovery
from localization.workflows.tracking import _recovery, _steer


class _Pilot:
    """A pilot that records the beliefs it was asked to steer on."""

    def __init__(self) -> None:
        self.asked: list[np.ndarray] = []

    def __call__(self, mean: np.ndarray) -> np.ndarray:
        self.asked.append(mean)
        return np.array([0.6, 0.1])


def test_recovery_lets_the_pilot_steer_unless_bumped_or_lost() -> None:
    rec = Recovery(w_max=1.0, back_off_steps=2, back_off_speed=0.3, look_rate=0.5, look_dwell=1)
    for info in (None, {}, {"belief_status": "tracking"}, {"belief_status": "doubtful"}):
        assert rec.act(0.2, info) is None
    back = np.array([-0.3, 0.0], np.float32)
    np.testing.assert_array_equal(rec.act(0.2, {"collision": True}), back)
    np.testing.assert_array_equal(rec.act(0.2, {}), back)  # two steps of reversing
    assert rec.act(0.2, {}) is None
    np.testing.assert_array_equal(rec.act(0.2, {"belief_status": "lost"}), [0.0, -0.5])
    rec.reset()
    assert rec.act(0.2, {}) is None


@pytest.mark.parametrize("name, value", [("w_max", 0.0), ("back_off_steps", -1),
                                         ("back_off_speed", 2.0), ("look_rate", -0.1),
                                         ("look_dwell", 1.5), ("hold_speed", -0.1),
                                         ("hold_speed", 1.5)])
def test_recovery_names_a_bad_argument(name: str, value: float) -> None:
    with pytest.raises((ValueError, TypeError), match=name):
        Recovery(**{name: value})


def test_tracking_drive_asks_its_pilot_only_when_recovery_does_not_act() -> None:
    pilot, mean = _Pilot(), np.array([1.0, 2.0, 0.3])
    rec = Recovery(look_rate=0.5)
    np.testing.assert_array_equal(_steer(pilot, None, mean, {"belief_status": "lost"}),
                                  [0.6, 0.1])  # recover=False: the pilot steers on any belief
    np.testing.assert_array_equal(_steer(pilot, rec, mean, {"belief_status": "lost"}),
                                  [0.0, -0.5])
    np.testing.assert_array_equal(_steer(pilot, rec, mean, {"belief_status": "tracking"}),
                                  [0.6, 0.1])
    assert len(pilot.asked) == 2


def test_hold_speed_keeps_the_course_while_the_belief_is_unconfirmed() -> None:
    """With ``hold_speed`` a "relocalizing" belief is not steered on: straight on at that
    speed; contacts still back off first and "lost" still looks around; without it the
    pilot steers on an unconfirmed belief as before."""
    assert Recovery().act(0.2, {"belief_status": "relocalizing"}) is None
    rec = Recovery(back_off_steps=1, back_off_speed=0.3, look_rate=0.5, hold_speed=0.25)
    hold = np.array([0.25, 0.0], np.float32)
    np.testing.assert_array_equal(rec.act(0.2, {"belief_status": "relocalizing"}), hold)
    np.testing.assert_array_equal(
        rec.act(0.2, {"belief_status": "relocalizing", "collision": True}),
        np.array([-0.3, 0.0], np.float32))
    np.testing.assert_array_equal(rec.act(0.2, {"belief_status": "relocalizing"}), hold)
    np.testing.assert_array_equal(rec.act(0.2, {"belief_status": "lost"}), [0.0, -0.5])
    for status in ("tracking", "doubtful"):
        assert rec.act(0.2, {"belief_status": status}) is None


def test_a_drive_takes_true_false_or_its_own_recovery() -> None:
    assert _recovery(False, 1.0) is None
    default = _recovery(True, 0.8)
    assert isinstance(default, Recovery) and default.w_max == 0.8 and default.hold_speed is None
    own = Recovery(hold_speed=0.3)
    own.act(0.0, {"collision": True})  # mid back-off: the drive starts it afresh
    assert _recovery(own, 1.0) is own and own.act(0.0, {}) is None
    with pytest.raises(TypeError, match="recover"):
        _recovery("yes", 1.0)  # type: ignore[arg-type]
