"""Kidnapping: teleport the robot to a random free street pose, unannounced.

The kidnapped robot problem tests whether a localizer notices that it is lost and
recovers (Fox, Burgard & Thrun, "Markov localization for mobile robots in dynamic
environments", JAIR 1999, which kidnap with a probability of 0.005 per metre driven).
:class:`KidnapWrapper` teleports the robot with ``env.unwrapped.set_pose``

- at given steps after each reset (``at_steps``), and/or
- as a Poisson process in the distance driven (``rate_per_metre``): the gap to the next
  kidnap is exponential with mean ``1 / rate_per_metre`` metres of true odometry.

A kidnap happens *before* the step's control is applied: the robot is put down at rest on
a random lane pose of the city's streets (:func:`envs.lanes.lane_poses`: a street both
ways or a turn, heading along the lane, clear of buildings) at least ``min_distance``
metres from where it was, then the step runs from there; the step's observation is the
first image seen at the new place. ``info["kidnapped"]`` is True on that step (False on
every other step and on reset); the reward does not count the jump in the distance to the
goal. The wrapper only reports it in ``info``: a filter fed from the observation is never
told.

``push=(low, high)`` makes each kidnap a shove instead: the robot is moved sideways, to
either side, by a distance drawn in ``[low, high]`` metres and turned by up to
:data:`PUSH_TURN` rad, to a pose clear of buildings (``min_distance`` does not apply; where
no such pose is found in ``_MAX_TRIES`` draws it stays put). :data:`PUSH_DISTANCE`
(0.8-1.6 m) takes a robot on a lane off the localizers' training tube (within 0.3 m of the
lanes) without leaving its street: the case of a robot pushed off its lane.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from envs.datasets import POSE_MARGIN
from envs.lanes import lane_poses

__all__ = ["KIDNAP_RATE_PER_METRE", "PUSH_DISTANCE", "PUSH_TURN", "KidnapWrapper"]

KIDNAP_RATE_PER_METRE = 0.005  # Fox, Burgard & Thrun's protocol
#: m, the range of a push's sideways shove (``push``; the robustness benchmark's "push" rows)
PUSH_DISTANCE = (0.8, 1.6)
#: rad, the largest turn of a push
PUSH_TURN = 0.5
_MAX_TRIES = 1000


class KidnapWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Teleport the robot of an ``AppearanceNav-v0`` env (see the module docstring).

    Parameters
    ----------
    env : gym.Env
        An AppearanceNav env, wrapped or not (``env.unwrapped`` has ``set_pose`` and ``city``).
    at_steps : iterable of int
        Steps (1 = the first step after reset) that start with a kidnap.
    rate_per_metre : float or None
        Kidnaps per metre driven (e.g. ``KIDNAP_RATE_PER_METRE`` = 0.005); None: none.
    min_distance : float
        Smallest distance (m) between the pose before and after a kidnap.
    seed : int or None
        Seeds the kidnap poses and distances; ``reset(seed=s)`` re-seeds them from s.
    lanes : {"streets", "route"}
        Lanes the new pose is drawn around (:func:`envs.lanes.lane_poses`).
    push : (float, float) or None
        ``(low, high)``: each kidnap shoves the robot sideways by a distance in that range
        (m) instead (see the module docstring); None: a teleport.

    Attributes
    ----------
    kidnaps : int
        Kidnaps since the last reset.
    odometer : float
        True distance driven (m) since the last reset.
    """

    def __init__(self, env: gym.Env, at_steps: Iterable[int] = (),
                 rate_per_metre: float | None = None, min_distance: float = 5.0,
                 seed: int | None = None, lanes: str = "streets",
                 push: tuple[float, float] | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, at_steps=tuple(at_steps), rate_per_metre=rate_per_metre,
            min_distance=min_distance, seed=seed, lanes=lanes, push=push)
        gym.Wrapper.__init__(self, env)
        base = env.unwrapped
        if not (hasattr(base, "set_pose") and hasattr(base, "city")):
            raise TypeError(f"env must be an AppearanceNav env (with set_pose and city), got "
                            f"{type(base).__name__}")
        steps = tuple(at_steps)
        if any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1
               for s in steps):
            raise ValueError(f"at_steps must be integers >= 1, got {steps}")
        if rate_per_metre is not None and not (math.isfinite(rate_per_metre)
                                               and rate_per_metre > 0):
            raise ValueError(f"rate_per_metre must be a positive number or None, got "
                             f"{rate_per_metre}")
        if not (math.isfinite(min_distance) and min_distance >= 0):
            raise ValueError(f"min_distance must be a number >= 0, got {min_distance}")
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
            raise TypeError(f"seed must be an int or None, got {seed!r}")
        lane_poses(base.city, 1, np.random.default_rng(0), lanes=lanes)  # validates lanes
        self.at_steps = frozenset(int(s) for s in steps)
        self.rate_per_metre = None if rate_per_metre is None else float(rate_per_metre)
        self.min_distance, self.lanes = float(min_distance), lanes
        self.push = None if push is None else _check_push(push)
        self._rng = np.random.default_rng(seed)
        self._steps, self.kidnaps, self.odometer = 0, 0, 0.0
        self._next_at = math.inf
        self._pose: NDArray[np.float64] | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        """Reset the env (``seed`` also re-seeds the kidnaps) and the kidnap schedule."""
        obs, info = super().reset(seed=seed, options=options)
        if seed is not None:
            self._rng = np.random.default_rng([int(seed), 0x4B1D])
        self._steps, self.kidnaps, self.odometer = 0, 0, 0.0
        self._next_at = self._draw_gap()
        self._pose = np.asarray(info["pose"], dtype=np.float64).copy()
        info["kidnapped"] = False
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Kidnap first when due (see the module docstring), then step the env."""
        if self._pose is None:
            raise RuntimeError("call reset() before step()")
        self._steps += 1
        kidnap = self._steps in self.at_steps or self.odometer >= self._next_at
        jump = 0.0
        if kidnap:
            jump = self._kidnap()
        obs, reward, terminated, truncated, info = super().step(action)
        pose = np.asarray(info["pose"], dtype=np.float64)
        self.odometer += float(np.hypot(*(pose[:2] - self._pose[:2])))
        self._pose = pose.copy()
        info["kidnapped"] = kidnap
        return obs, float(reward) + jump, terminated, truncated, info

    def _draw_gap(self) -> float:
        if self.rate_per_metre is None:
            return math.inf
        return self.odometer + float(self._rng.exponential(1.0 / self.rate_per_metre))

    def sample_pose(self, avoid: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """A random free lane pose (3,) at least ``min_distance`` from ``avoid`` (x, y)."""
        city = self.env.unwrapped.city
        for _ in range(_MAX_TRIES):
            pose = lane_poses(city, 1, self._rng, lanes=self.lanes, margin=POSE_MARGIN)[0][0]
            if avoid is None or np.hypot(*(pose[:2] - avoid[:2])) >= self.min_distance:
                return pose
        raise RuntimeError(f"no free street pose {self.min_distance} m away from {avoid}: "
                           "lower min_distance")

    def push_pose(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """``pose`` (3,) shoved sideways by a distance in ``push`` and turned by up to
        :data:`PUSH_TURN`, clear of buildings (``pose`` itself when no draw is)."""
        city, (low, high) = self.env.unwrapped.city, self.push
        side = np.array([-np.sin(pose[2]), np.cos(pose[2])])
        for _ in range(_MAX_TRIES):
            xy = pose[:2] + self._rng.uniform(low, high) * self._rng.choice([-1.0, 1.0]) * side
            if city.free_mask(xy[None], POSE_MARGIN)[0]:
                yaw = pose[2] + self._rng.uniform(-PUSH_TURN, PUSH_TURN)
                return np.array([xy[0], xy[1], math.remainder(yaw, 2 * math.pi)])
        return np.asarray(pose, dtype=np.float64).copy()

    def _kidnap(self) -> float:
        """Teleport (or push); return the reward correction (distance to goal after -
        before)."""
        base = self.env.unwrapped
        before = base.pose
        pose = self.sample_pose(before) if self.push is None else self.push_pose(before)
        base.set_pose(pose)
        self._pose = base.pose.copy()
        self.kidnaps += 1
        self._next_at = self._draw_gap()
        goal = getattr(base, "goal", None)
        if goal is None:
            return 0.0
        return float(np.hypot(*(pose[:2] - goal)) - np.hypot(*(before[:2] - goal)))


def _check_push(push: Any) -> tuple[float, float]:
    """``push`` as (low, high) with 0 <= low <= high, finite."""
    try:
        low, high = (float(v) for v in push)
    except (TypeError, ValueError):
        raise ValueError(f"push must be (low, high) metres, got {push!r}") from None
    if not (math.isfinite(high) and 0.0 <= low <= high):
        raise ValueError(f"push must be (low, high) metres with 0 <= low <= high, got {push!r}")
    return low, high
