"""What a pilot does when it should not steer on the belief: back off after a contact, look
around while the belief is lost, and (optionally) keep its course while it is unconfirmed.

Shared by :class:`agents.scripted.ScriptedAgent` and the closed-loop tracking drives
(:mod:`localization.workflows.tracking`, ``recover=True``): any controller that steers on a
belief mean can ask a :class:`Recovery` first and steer only when it returns None.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from localization._validation import check_int, check_real
from localization.geometry import wrap_angle

__all__ = ["HOLD_STATUSES", "LOOK_TOLERANCE", "STOP_STATUSES", "Recovery", "street_axis"]

#: ``info["belief_status"]`` values on which a pilot does not steer on the belief
STOP_STATUSES = ("lost",)
#: ``info["belief_status"]`` values on which a pilot with ``hold_speed`` keeps its course: a
#: belief started or restarted at one image's psi* and not yet confirmed by the next ones
HOLD_STATUSES = ("relocalizing",)
#: While lost the pilot turns to the street axes (multiples of pi/2: the city's streets run
#: along x and y), the headings a lane-trained map has views at; within this many rad of one
#: it stops turning and looks.
LOOK_TOLERANCE = 0.05


def street_axis(yaw: float) -> float:
    """The street direction (a multiple of pi/2) nearest to heading ``yaw`` (rad)."""
    return float(np.round(yaw / (np.pi / 2)) * (np.pi / 2))


class Recovery:
    """Back off after contacts and look around while lost, before a pilot steers.

    Parameters
    ----------
    w_max : float — bound on the angular velocity command (rad/s).
    back_off_steps : int — steps it reverses after a contact (0: never).
    back_off_speed : float — reversing speed (m/s).
    look_rate : float — turn rate (rad/s) while it looks around.
    look_dwell : int — steps it looks along each street axis while lost.
    hold_speed : float or None — speed (m/s) at which it keeps its course (w = 0) while the
        belief is unconfirmed; None (the default): the pilot steers on it as on any belief.

    Notes
    -----
    :meth:`act` takes the believed heading and the step's ``info`` and returns the action
    U = [v, w] (float32), or None when the pilot may steer on the belief.

    - ``info["collision"]`` (a bump sensor: contact with a building, the boundary or a
      vehicle) makes it reverse ``back_off_steps`` steps at ``back_off_speed`` (forward
      instead if the contact lasts through two steps of reversing: the obstacle is behind;
      reversing on held one kidnapped robot against a wall for 239 steps). A plan on a wrong
      belief led into the wall, and pressing on only adds contact (on tuning cities 13-14
      backing off 5 steps cut the contact steps per episode of the scripted agent on the EKF
      belief from 2.6 to 0.46 nominal and 15.9 to 2.2 kidnapped, success unchanged).
    - ``info["belief_status"]`` "lost": it stops, turns in place at ``look_rate`` to the
      street axis nearest its believed heading (the views a lane-trained map knows), looks
      along it for ``look_dwell`` steps, then turns a quarter turn on to the next axis, and
      so on (turning at one rate through the views off the map lost beliefs that were
      right: a lane map rejects them all until the 50-step restart jumps to a look-alike).
    - ``info["belief_status"]`` "relocalizing" and ``hold_speed`` set: it drives straight on
      at ``hold_speed``. A start or restart at an aliased psi* is a belief metres off; a
      pilot steering on it turns the robot off its lane, where a lane-trained map knows no
      view that could correct it. Held on course along its street, the robot keeps seeing
      views the map knows until a later image's psi* replaces the trial belief (on the 60 m
      tuning cities 53, 56 and 57, 120 tours of the tracking drives, docs/benchmarks.md
      §10: belief RMSE pooled 0.461 -> 0.333 m at 0.3 m/s).

    Call :meth:`reset` between episodes.
    """

    def __init__(self, w_max: float = 1.0, back_off_steps: int = 5,
                 back_off_speed: float = 0.3, look_rate: float = 0.5,
                 look_dwell: int = 10, hold_speed: float | None = None) -> None:
        self.w_max = check_real(w_max, "w_max", low=0.0, low_open=True)
        self.back_off_steps = check_int(back_off_steps, "back_off_steps", low=0)
        self.back_off_speed = check_real(back_off_speed, "back_off_speed", low=0.0, high=1.0)
        self.look_rate = check_real(look_rate, "look_rate", low=0.0)
        self.look_dwell = check_int(look_dwell, "look_dwell", low=0)
        self.hold_speed = (None if hold_speed is None
                           else check_real(hold_speed, "hold_speed", low=0.0, high=1.0))
        self.reset()

    def reset(self) -> None:
        """Stop reversing and looking."""
        self._backing = 0  # steps of backing off left
        self._back_sign = -1.0  # -1 reversing, +1 forward (the contact came while reversing)
        self._look_axis: float | None = None  # while lost: the street axis it turns to
        self._look_left = 0  # steps it still looks along that axis

    def act(self, yaw: float, info: Mapping[str, Any] | None) -> NDArray[np.float32] | None:
        """The action for believed heading ``yaw`` (rad) and the step's ``info``; None when
        the pilot may steer on the belief."""
        if info is not None and info.get("collision", False):
            self._bump()
        if self._backing > 0:
            self._backing -= 1
            return np.array([self._back_sign * self.back_off_speed, 0.0], dtype=np.float32)
        if info is not None and info.get("belief_status") in STOP_STATUSES:
            return self._look_around(float(yaw))
        self._look_axis = None
        if (self.hold_speed is not None and info is not None
                and info.get("belief_status") in HOLD_STATUSES):
            return np.array([self.hold_speed, 0.0], dtype=np.float32)
        return None

    def _bump(self) -> None:
        """A contact: back off ``back_off_steps`` steps, reversing; forward instead when the
        contact lasts past the first two steps of reversing (the obstacle is behind: reversing
        on pressed into it)."""
        if self._backing == 0:
            self._back_sign, self._backing = -1.0, self.back_off_steps
        elif self._back_sign < 0 and self._backing < self.back_off_steps - 1:
            self._back_sign, self._backing = 1.0, self.back_off_steps

    def _look_around(self, yaw: float) -> NDArray[np.float32]:
        """Lost: turn on the spot to the nearest street axis of the believed heading ``yaw``,
        look along it for ``look_dwell`` steps, then turn on a quarter turn to the next."""
        if self._look_axis is None:
            self._look_axis, self._look_left = street_axis(yaw), self.look_dwell
        error = float(wrap_angle(self._look_axis - yaw))
        if abs(error) <= LOOK_TOLERANCE:
            if self._look_left > 0:
                self._look_left -= 1
                return np.zeros(2, dtype=np.float32)
            self._look_axis, self._look_left = self._look_axis + np.pi / 2, self.look_dwell
            error = float(wrap_angle(self._look_axis - yaw))
        return np.array([0.0, np.copysign(min(self.look_rate, self.w_max), error)],
                        dtype=np.float32)
