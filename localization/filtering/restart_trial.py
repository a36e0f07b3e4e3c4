"""RestartTrial: a belief (re)started from images, on probation until the next images agree.

One image's psi* can be a look-alike place metres away, and a run of aliased images can
agree on a wrong place for a step or two, while the images after it do not. So every restart
of :class:`~localization.filtering.belief.BeliefFilter` (its start from the first image, the
restart after ``relocalize_after`` misses, a divergence restart) is on trial: it is
confirmed by ``CONFIRM_STEPS`` accepted measurements within ``TRIAL_STEPS`` steps that have a
measurement (an image off the maps tells nothing); otherwise it failed, and the EKF it
replaced (which runs on beside it with the same F and images) comes back, or, with nothing to
come back to, the belief starts again at a later image's psi*.
"""

from __future__ import annotations

from dataclasses import dataclass

from localization.filtering.ekf import PoseEKF

__all__ = ["CONFIRM_STEPS", "TRIAL_STEPS", "RestartTrial"]

CONFIRM_STEPS = 3  # accepted measurements after a restart before the status is "tracking"
TRIAL_STEPS = 5  # a restart must have CONFIRM_STEPS accepted within these, or fails


@dataclass
class RestartTrial:
    """The bookkeeping of one restart on trial.

    Attributes
    ----------
    replaced : PoseEKF or None
        The EKF the restart replaced (None: nothing to come back to).
    misses : int
        The replaced EKF's steps in a row without an accepted measurement.
    steps, accepted : int
        The restart's steps with a measurement, and its accepted ones.
    """

    replaced: PoseEKF | None
    misses: int
    steps: int = 0
    accepted: int = 0

    def record(self, status: str) -> None:
        """Count one step of the restarted EKF with measurement status ``status``."""
        self.steps += status != "out_of_domain"
        self.accepted += status == "accepted"

    @property
    def confirmed(self) -> bool:
        return self.accepted >= CONFIRM_STEPS

    @property
    def failed(self) -> bool:
        return not self.confirmed and self.steps >= TRIAL_STEPS
