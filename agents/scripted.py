"""A scripted navigator: plan over the street graph, follow with pure pursuit on the belief.

The robot knows the map (the city's street graph) but not its pose: every decision uses the
belief mean ``obs["pose_mean"]`` of a pose-belief observation
``Dict(pose_mean=(3,), pose_cov=(6,), goal=(2,))`` (``localization.wrappers``: the GSE belief,
dead reckoning or the oracle). The agent never sees the true pose.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.guard import ImageGuard
from agents.planner import (
    BELIEF_OUTSIDE_FRACTION,
    PlannedPath,
    StreetPlanner,
    check_city_point,
    clamp_to_city,
    round_corners,
)
from agents.recovery import LOOK_TOLERANCE, STOP_STATUSES, Recovery, street_axis
from envs.driving import bearing, pursuit_turn_rate
from localization._validation import check_array, check_bool, check_int, check_real
from localization.geometry import Array

__all__ = ["BELIEF_KEYS", "LOOK_TOLERANCE", "PLANS", "SLOW_STATUSES", "STOP_STATUSES", "Navigator",
           "ScriptedAgent", "check_belief_observation", "pure_pursuit", "street_axis"]

BELIEF_KEYS = ("pose_mean", "pose_cov", "goal")
SLOW_STATUSES = ("relocalizing", "ambiguous", "doubtful")
OBS_NAMES = ("obs['pose_mean']", "obs['goal']")  # how Navigator.update names them in errors


def check_belief_observation(obs: Any) -> tuple[Array, Array, Array]:
    """Validate a belief observation; return (pose_mean (3,), pose_cov (6,), goal (2,)) float64.

    Raises
    ------
    TypeError
        If ``obs`` is not a mapping.
    ValueError
        If ``obs`` lacks the belief keys (e.g. the raw image observation of an unwrapped env),
        or a value has the wrong shape or is not finite.
    """
    if not isinstance(obs, Mapping):
        raise TypeError(f"expected a belief observation dict with keys {list(BELIEF_KEYS)}, "
                         f"got {type(obs).__name__}")
    missing = [k for k in BELIEF_KEYS if k not in obs]
    if missing:
        raise ValueError(
            f"the observation lacks the belief keys {missing} (it has {sorted(obs)}): wrap the env "
            "in a pose source from localization.wrappers (BeliefWrapper, DeadReckoningWrapper or "
            "OracleWrapper) before giving its observations to an agent")
    mean, cov, goal = (check_array(obs[key], f"obs[{key!r}]", shape=(size,))
                       for key, size in zip(BELIEF_KEYS, (3, 6, 2)))
    return mean, cov, goal


def pure_pursuit(pose: Array, carrot: Array, remaining: float, speed: float, w_max: float,
                 turn_in_place: float) -> Array:
    """Pure-pursuit control U = [v, w] (2,) steering the pose [x, y, yaw] towards ``carrot``.

    Turns on the spot when the carrot is more than ``turn_in_place`` rad off the heading (the
    streets are narrow); slows down over the last metre (``remaining`` m to the goal).
    """
    alpha = bearing(pose, carrot)
    if abs(alpha) > turn_in_place:
        return np.array([0.0, np.copysign(w_max, alpha)])
    v = speed * np.cos(alpha) * min(1.0, 0.5 + remaining)
    distance = np.hypot(carrot[0] - pose[0], carrot[1] - pose[1])
    w = pursuit_turn_rate(alpha, max(v, 0.2), max(distance, 0.2), w_max)
    return np.array([v, w])


#: the kinds of plan a :class:`Navigator` makes
PLANS = ("drive", "shortest")


class Navigator:
    """The plan to the current goal and the progress along it, from belief means.

    ``plan="drive"`` (the default) plans like a car (:meth:`agents.planner.StreetPlanner.drive`:
    lanes and rounded corners, no U-turns), the kind of driving a lane-trained localizer
    knows. ``plan="shortest"`` takes the shortest street path
    (:meth:`~agents.planner.StreetPlanner.plan`, corners rounded the same way: U-turns
    anywhere, turning on the spot where the path doubles back), for a localizer trained on the whole street surface at
    every heading (``fit_city_localizer(lanes="free")``). A new goal starts a new plan; the
    plan is also redone from the belief mean when the mean is farther than
    ``replan_distance`` from it (after a belief correction, say).

    Parameters
    ----------
    city : envs.scene.City — the map.
    replan_distance : float — metres off the path that trigger a new plan.
    plan : {"drive", "shortest"}
    """

    def __init__(self, city: Any, replan_distance: float = 1.0, plan: str = "drive") -> None:
        if plan not in PLANS:
            raise ValueError(f"unknown plan {plan!r}; choose one of {PLANS}")
        self.planner, self.plan = StreetPlanner(city), plan
        self.replan_distance = check_real(replan_distance, "replan_distance", low=0.0, low_open=True)
        self.reset()

    def reset(self) -> None:
        """Forget the plan."""
        self.goal: Array | None = None
        self.path: PlannedPath | None = None
        self.replans = 0

    def update(self, pose: Array, goal: Array, names: tuple[str, str] = ("pose", "goal")
               ) -> PlannedPath:
        """Plan (or replan) as needed for the believed pose [x, y, yaw] and advance the
        progress along the plan (``names``: the arguments' names in error messages).

        A believed pose that coasted off the map (up to ``BELIEF_OUTSIDE_FRACTION`` of the
        city's side) is planned from the nearest point of the city.

        Raises
        ------
        ValueError
            If the pose or the goal is malformed or far outside the city.
        """
        city = self.planner.city
        pose = clamp_to_city(check_city_point(pose, names[0], city, sizes=(3,),
                                              outside_fraction=BELIEF_OUTSIDE_FRACTION), city)
        goal = check_city_point(goal, names[1], city, sizes=(2,))
        new_goal = self.goal is None or not np.allclose(goal, self.goal)
        if new_goal or self.path.distance_to(pose[:2]) > self.replan_distance:
            self.replans += not new_goal
            self.goal = np.array(goal, dtype=np.float64)
            self.path = PlannedPath(self.planner.drive(pose, goal) if self.plan == "drive" else
                                    round_corners(self.planner.plan(pose[:2], goal),
                                                  self.planner.turn_radius))
        self.path.update(pose[:2])
        return self.path


class ScriptedAgent:
    """Plan a street path to the goal and follow it with pure pursuit on the belief mean.

    Parameters
    ----------
    city : envs.scene.City
        The map (``env.unwrapped.city``).
    lookahead : float — carrot distance (m) along the path.
    speed : float — cruise speed command (m/s).
    w_max : float — bound on the angular velocity command (rad/s).
    turn_in_place : float — heading error (rad) above which the robot turns on the spot.
    replan_distance : float — see :class:`Navigator`.
    plan : {"drive", "shortest"} — car-like lane plans, or the shortest street path with
        turns on the spot (:class:`Navigator`).
    back_off_steps : int — steps it reverses after a contact (0: never).
    back_off_speed : float — reversing speed (m/s).
    look_rate : float — turn rate (rad/s) while it looks around, lost.
    look_dwell : int — steps it looks along each street axis while lost.
    slow_steps : int or None — the most consecutive steps of a slow status it drives at
        ``slow_factor`` before it drives at full speed again (until the status has been
        "tracking" or "lost" for a step); None: for as long as the status lasts.
    guard : bool — veto driving forward into a building from where the latest image alone
        puts the robot (``info["image_pose"]``, :class:`~agents.guard.ImageGuard`).
    guard_patience : int or None — the guard's ``patience``: consecutive vetoes after which
        it lets forward commands through for a while (None: it never yields).
    guard_agree : float or None — the guard's ``agree``: it yields only while the image pose
        lies this close (m) to the belief (None: whatever the belief).
    guard_memory : int — the guard's ``memory``: earlier steps' image poses, carried forward
        by the motion model with every command the agent sent, also veto (0: the latest only).

    Notes
    -----
    ``act(obs, info)`` takes one belief observation (keys ``pose_mean``, ``pose_cov``,
    ``goal``) and, optionally, the step's ``info``, and returns the action U = [v, w]
    (float32, inside the env's action Box). Before it steers, its
    :class:`~agents.recovery.Recovery` (``self.recovery``) may act instead: after a contact
    (``info["collision"]``, a bump sensor) it reverses ``back_off_steps`` steps at
    ``back_off_speed``; while ``info["belief_status"]`` is "lost" it does not steer on the
    belief but stops and looks along the street axes (``look_rate``, ``look_dwell``).
    "relocalizing", "doubtful" or "ambiguous" scale the speed by ``slow_factor``, for at
    most ``slow_steps`` steps at a stretch (0.25: on tuning cities 13-14, robots pushed off
    their lane on the particle belief touched a wall for 0.50 steps per episode against 0.83
    at 0.5, 100 episodes, at 0.9 s more per goal; at 0 the agent stalled, 0.95 of the goals).
    The status and the bumper come through ``info``, not the observation, so every pose
    source keeps the same observation space (and trained policies keep working).
    Call :meth:`reset` between episodes (a new goal also starts a new plan).
    """

    def __init__(self, city: Any, lookahead: float = 0.6, speed: float = 0.9, w_max: float = 1.0,
                 turn_in_place: float = 0.6, replan_distance: float = 1.0,
                 look_rate: float = 0.5, slow_factor: float = 0.25, plan: str = "drive",
                 back_off_steps: int = 5, back_off_speed: float = 0.3,
                 look_dwell: int = 10, guard: bool = False, slow_steps: int | None = None,
                 guard_patience: int | None = None, guard_agree: float | None = None,
                 guard_memory: int = 0) -> None:
        self.navigator = Navigator(city, replan_distance, plan)
        self.slow_steps = None if slow_steps is None else check_int(slow_steps, "slow_steps",
                                                                    low=1)
        self._slow_run = 0
        self.recovery = Recovery(w_max, back_off_steps, back_off_speed, look_rate, look_dwell)
        self.slow_factor = check_real(slow_factor, "slow_factor", low=0.0, high=1.0)
        self.guard = (ImageGuard(city, patience=guard_patience, agree=guard_agree,
                                 memory=guard_memory) if check_bool(guard, "guard") else None)
        self.lookahead, self.speed, self.w_max, self.turn_in_place = (
            check_real(v, name, low=0.0, low_open=True) for name, v in (
                ("lookahead", lookahead), ("speed", speed), ("w_max", w_max),
                ("turn_in_place", turn_in_place)))

    def reset(self) -> None:
        """Forget the current plan (and stop reversing)."""
        self.navigator.reset()
        self.recovery.reset()
        self._slow_run = 0
        if self.guard is not None:
            self.guard.reset()

    @property
    def path(self) -> Array | None:
        """The current plan (p, 2) resampled every 5 cm, or None before the first action."""
        path = self.navigator.path
        return None if path is None else path.points

    def act(self, obs: Mapping[str, Any], info: Mapping[str, Any] | None = None
            ) -> NDArray[np.float32]:
        """The action U = [v, w] for one belief observation (and the step's ``info``)."""
        mean, _, goal = check_belief_observation(obs)
        u = self._command(mean, goal, info)
        if self.guard is not None:
            self.guard.remember(u, info)
        return u

    def _command(self, mean: Array, goal: Array, info: Mapping[str, Any] | None
                 ) -> NDArray[np.float32]:
        """The recovery's command, or pure pursuit along the plan (slowed, guarded)."""
        slow = self._slow(info)
        u_recover = self.recovery.act(float(mean[2]), info)
        if u_recover is not None:
            return u_recover
        path = self.navigator.update(mean, goal, OBS_NAMES)
        u = pure_pursuit(mean, path.ahead(self.lookahead), path.remaining(), self.speed,
                         self.w_max, self.turn_in_place)
        if slow:
            u[0] *= self.slow_factor
        if self.guard is not None:
            u = self.guard.filter(u, mean, info)
        return u.astype(np.float32)

    def _slow(self, info: Mapping[str, Any] | None) -> bool:
        """Whether this step drives at ``slow_factor``: a slow status, within ``slow_steps``
        consecutive steps of it (counted on every step, recovering ones included)."""
        status = None if info is None else info.get("belief_status")
        self._slow_run = self._slow_run + 1 if status in SLOW_STATUSES else 0
        return self._slow_run > 0 and (self.slow_steps is None
                                       or self._slow_run <= self.slow_steps)
