"""How :class:`~localization.filtering.belief.BeliefFilter` names its state (a mixin): the
``belief_status`` after each step from the update's status, the misses, the width of P, the
divergence monitor's verdict and contacts (docs/method.md §13).

The host class provides ``ekf``, ``misses``, ``belief_status``, ``_confirm``, ``_forced``,
``_repeat_view``, ``_trial``, ``_bumped`` and ``_lost_now`` / ``_doubtful_now``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering.ekf import PoseEKF
from localization.filtering.restart_trial import CONFIRM_STEPS

__all__ = ["LOST_AFTER_MISSES", "LOST_HEADING_STD", "LOST_POSITION_STD", "StatusMixin"]

LOST_AFTER_MISSES = 5  # steps in a row without an accepted measurement: "doubtful" or "lost"
#: ... "lost" when P is also this wide (position std in m along its widest axis, heading std in
#: rad); else "doubtful": dead reckoning through unfamiliar views at a corner is not being lost
LOST_POSITION_STD = 0.5
#: wider than the inflation: rejected images alone are "doubtful" (0.4 rad stopped a belief
#: 0.1 m right to turn in place into views off the map; tuning cities 13-16, method §13)
LOST_HEADING_STD = 0.6


class StatusMixin:
    """``belief_status`` of the belief filter."""

    ekf: PoseEKF | None
    misses: int
    belief_status: str
    _confirm: int
    _forced: bool
    _repeat_view: bool
    _trial: Any
    _bumped: int
    _lost_now: bool
    _doubtful_now: bool

    def _update_status(self, status: str) -> None:
        """"relocalizing" until ``CONFIRM_STEPS`` accepted measurements; otherwise "lost"
        while the monitor says so, or after ``LOST_AFTER_MISSES`` steps in a row without an
        accepted measurement once P is wider than ``LOST_POSITION_STD`` /
        ``LOST_HEADING_STD`` (wider than the heading inflation makes it), or after a
        contact that contradicts it (a restart on trial too, "relocalizing" again after it:
        on tuning city 13, seed 3000010 kidnapped, a restart 2.6 m off whose images all fell
        off the maps stayed "relocalizing" for 270 steps and drove into a kiosk 30 times);
        "doubtful" after those misses while P is still narrow (coasting on F through views
        off the maps) or on a step whose image alone contradicts the belief (the monitor's
        ``doubt_nis``); else "tracking"."""
        if status == "relocalized":
            return
        if status == "reverted":
            self.belief_status = "doubtful"
            return
        on_trial = self.belief_status == "relocalizing" or (
            self.belief_status == "lost" and self._trial is not None)  # lost by a contact
        if on_trial and not self._bumped:
            self.belief_status = "relocalizing"
            self._confirm += status == "accepted" and not (self._forced or self._repeat_view)
            if self._confirm >= CONFIRM_STEPS:
                self.belief_status = "tracking"
            return
        missing = self.misses >= LOST_AFTER_MISSES
        lost = self._lost_now or (missing and self._wide()) or self._bumped > 0
        self.belief_status = "lost" if lost else "doubtful" if (
            self._doubtful_now or missing) else "tracking"

    def _wide(self) -> bool:
        """P too wide to steer on (:data:`LOST_POSITION_STD`, :data:`LOST_HEADING_STD`)."""
        assert self.ekf is not None
        P = self.ekf.P
        return bool(np.linalg.eigvalsh(P[:2, :2])[-1] > LOST_POSITION_STD ** 2
                    or P[2, 2] > LOST_HEADING_STD ** 2)
