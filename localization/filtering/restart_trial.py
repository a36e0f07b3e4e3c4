"""RestartTrial: a belief (re)started from images, on probation until the next images agree.

One image's psi* can be a look-alike place metres away, and a run of aliased images can
agree on a wrong place for a step or two, while the images after it do not. So every restart
of :class:`~localization.filtering.belief.BeliefFilter` (its start from the first image, the
restart after ``relocalize_after`` misses, a divergence restart) is on trial: it is
confirmed by ``CONFIRM_STEPS`` accepted measurements within ``TRIAL_STEPS`` steps that have a
measurement (an image off the maps tells nothing); otherwise it failed, and the EKF it
replaced (which runs on beside it with the same F and images) comes back, or, with nothing to
come back to, the belief starts again at a later image's psi*.

Only views the robot took from somewhere else count: a measured step is a *repeat* until the
odometry (the predicted motion, never the updates) has carried the belief ``VIEW_TRAVEL`` m
or turned it ``VIEW_TURN`` rad since the last counted view. A robot standing still (pressed
against a vehicle, a contact step predicted as blocked) sees the same picture again and
again, and a look-alike's psi* agrees with itself every time: on held-out city 31 (stop 34)
one repeated view confirmed a restart 22 m away, which then stood for 200 steps. A moving
robot's every step counts (0.045 m at the scripted agent's half speed, 0.05 rad per step of
its look turns); after ``TRIAL_REPEATS`` repeats the trial fails. A contact step predicted as
blocked adds no odometry (``BeliefFilter._odometry``): its commanded turn is as uncertain as
it is large, and a robot pinned on a building while its pilot commands a turn sees one view.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from localization.filtering.ekf import PoseEKF

__all__ = ["CONFIRM_STEPS", "TRIAL_REPEATS", "TRIAL_STEPS", "VIEW_TRAVEL", "VIEW_TURN",
           "RestartTrial", "ViewOdometer"]

CONFIRM_STEPS = 3  # accepted measurements after a restart before the status is "tracking"
TRIAL_STEPS = 5  # a restart must have CONFIRM_STEPS accepted within these, or fails
VIEW_TRAVEL = 0.03  # m of odometry between two counted views (a third of a 0.9 m/s step)
VIEW_TURN = 0.03  # rad of odometry between two counted views
TRIAL_REPEATS = 15  # measured steps from the same view after which a trial fails


@dataclass
class ViewOdometer:
    """Odometry (m, rad) since the last counted view: the next image is a view from
    somewhere else once it reaches :data:`VIEW_TRAVEL` or :data:`VIEW_TURN`."""

    travel: float = 0.0
    turn: float = 0.0

    def add(self, travel: float, turn: float) -> None:
        """Add one step's predicted travel (m) and turn (rad)."""
        self.travel += travel
        self.turn += turn

    @property
    def new_view(self) -> bool:
        return self.travel >= VIEW_TRAVEL or self.turn >= VIEW_TURN


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
        The restart's measured steps from new views, and its accepted ones.
    repeats : int
        Its measured steps from the view last counted (not in ``steps``).
    odometer : ViewOdometer
        Odometry since the last counted view (since the restart before the first).
    """

    replaced: PoseEKF | None
    misses: int
    steps: int = 0
    accepted: int = 0
    repeats: int = 0
    odometer: ViewOdometer = field(default_factory=ViewOdometer)

    def record(self, status: str, travel: float, turn: float) -> bool:
        """Count one step of the restarted EKF with measurement status ``status`` after
        odometry of ``travel`` m and ``turn`` rad; whether it counted as a new view (False
        for an image off the maps and for a repeat)."""
        self.odometer.add(travel, turn)
        if status == "out_of_domain":
            return False
        if not self.odometer.new_view:
            self.repeats += 1
            return False
        self.odometer = ViewOdometer()
        self.steps += 1
        self.accepted += status == "accepted"
        return True

    @property
    def confirmed(self) -> bool:
        return self.accepted >= CONFIRM_STEPS

    @property
    def stalled(self) -> bool:
        """Unconfirmed after ``TRIAL_REPEATS`` repeated views (the robot is not moving)."""
        return not self.confirmed and self.repeats >= TRIAL_REPEATS

    @property
    def failed(self) -> bool:
        return not self.confirmed and (self.steps >= TRIAL_STEPS or self.stalled)
