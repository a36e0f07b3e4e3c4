"""The RL agent's observation: the plan to the goal as seen from the believed pose.

A pose-belief observation ``Dict(pose_mean, pose_cov, goal)`` is turned into what a policy
needs to drive, all in the belief's body frame (x forward, y left) so the policy need not
learn the geometry of headings:

- ``waypoints`` (2 * len(lookaheads),): points of the planned street path (the
  :class:`agents.scripted.Navigator`, the same plan the scripted agent follows) ``lookaheads``
  metres ahead of the believed progress, in units of 2 m;
- ``goal`` (2,): the goal, in units of 10 m;
- ``uncertainty`` (3,): the belief's standard deviations of x, y (m) and yaw (rad);
- with ``status=True`` also ``status`` (len(BELIEF_STATUSES),): the belief's own verdict
  (``info["belief_status"]``: tracking, ambiguous, doubtful, lost, relocalizing) one-hot; a
  source without a status (the oracle, dead reckoning) counts as "tracking";
- with ``bumper=True`` also ``bumper`` (3,): the robot's bump sensor with a short memory,
  ``[BUMPER_DECAY ** k, cos b, sin b]`` with k the steps since the last contact
  (``info["collision"]``; 0 on the contact's step, and the first entry 0 before any
  contact) and b where it was touched (``info["collision_bearing"]``, 0 ahead; cos and sin
  0 when the side is unknown, as for a mover's push). Without it a policy cannot tell a
  wall from open street: on a belief 1 m off it pressed into a wall for the rest of the
  episode (the scripted agent reverses after a bump).

Values are clipped to their Box. The true pose is never used. Policies saved before the status
or the bumper existed have no ``status`` / ``bumper`` key (both False, the default).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from agents.scripted import OBS_NAMES, Navigator, check_belief_observation
from localization._validation import check_array, check_bool
from localization.filtering.divergence import BELIEF_STATUSES

__all__ = ["NavigationFeatures", "NavigationObservation", "status_one_hot"]

_TRIU = np.triu_indices(3)
_DIAG = [int(np.flatnonzero((_TRIU[0] == i) & (_TRIU[1] == i))[0]) for i in range(3)]
WAYPOINT_UNIT = 2.0  # m
GOAL_UNIT = 10.0  # m
LIMIT = 5.0  # Box bound of the scaled positions
STD_LIMIT = 10.0  # Box bound of the standard deviations
BUMPER_DECAY = 0.7  # the bumper's memory: its first entry a step after a contact


def to_body_frame(points: NDArray[np.float64], pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """World points (k, 2) in the frame of ``pose`` [x, y, yaw] (x forward, y left)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = points - pose[:2]
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])


class NavigationFeatures:
    """Stateful map from belief observations to the policy's observation (see the module doc).

    Parameters
    ----------
    city : envs.scene.City — the map.
    lookaheads : tuple of float — distances (m) ahead along the plan of the waypoints.
    replan_distance : float — see :class:`agents.scripted.Navigator`.
    status : bool — add the belief status one-hot (``status`` key).
    bumper : bool — add the bump sensor with its memory (``bumper`` key).
    """

    def __init__(self, city: Any, lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                 replan_distance: float = 1.0, status: bool = False,
                 bumper: bool = False) -> None:
        d = check_array(lookaheads, "lookaheads", ndim=1, what="(distances in m)")
        if len(d) == 0 or np.any(d <= 0):
            raise ValueError(f"lookaheads must be positive distances, got {lookaheads}")
        self.lookaheads = tuple(float(v) for v in d)
        self.status = check_bool(status, "status")
        self.bumper = check_bool(bumper, "bumper")
        self.navigator = Navigator(city, replan_distance)
        self.observation_space = self.space(self.lookaheads, self.status, self.bumper)
        self._touch = np.zeros(3, np.float32)  # the bumper entry

    @staticmethod
    def space(lookaheads: tuple[float, ...], status: bool = False,
              bumper: bool = False) -> spaces.Dict:
        """The observation space for these lookaheads (and the status one-hot, the bumper)."""
        keys = {
            "waypoints": spaces.Box(-LIMIT, LIMIT, (2 * len(lookaheads),), np.float32),
            "goal": spaces.Box(-LIMIT, LIMIT, (2,), np.float32),
            "uncertainty": spaces.Box(0.0, STD_LIMIT, (3,), np.float32),
        }
        if status:
            keys["status"] = spaces.Box(0.0, 1.0, (len(BELIEF_STATUSES),), np.float32)
        if bumper:
            keys["bumper"] = spaces.Box(-1.0, 1.0, (3,), np.float32)
        return spaces.Dict(keys)

    def reset(self) -> None:
        """Forget the plan and the last contact (call at episode starts)."""
        self.navigator.reset()
        self._touch = np.zeros(3, np.float32)

    def __call__(self, obs: Mapping[str, Any], status: str | None = None,
                 info: Mapping[str, Any] | None = None) -> dict[str, NDArray[np.float32]]:
        """The policy observation for one belief observation and the belief's status
        (``info["belief_status"]``; None: "tracking"; used only with ``status=True``);
        ``info``: the step's (its ``collision`` and ``collision_bearing``, read with
        ``bumper=True``; None at a reset). Call once per env step: the bumper remembers.

        Raises
        ------
        ValueError
            If ``status`` is not one of ``BELIEF_STATUSES``.
        """
        mean, cov, goal = check_belief_observation(obs)
        path = self.navigator.update(mean, goal, OBS_NAMES)
        ahead = np.array([path.ahead(d) for d in self.lookaheads])
        std = np.sqrt(np.clip(cov[_DIAG], 0.0, None))
        features = {
            "waypoints": np.clip(to_body_frame(ahead, mean).ravel() / WAYPOINT_UNIT,
                                 -LIMIT, LIMIT).astype(np.float32),
            "goal": np.clip(to_body_frame(goal[None], mean)[0] / GOAL_UNIT,
                            -LIMIT, LIMIT).astype(np.float32),
            "uncertainty": np.clip(std, 0.0, STD_LIMIT).astype(np.float32),
        }
        if self.status:
            features["status"] = status_one_hot(status)
        if self.bumper:
            features["bumper"] = self._bump(info)
        return features

    def _bump(self, info: Mapping[str, Any] | None) -> NDArray[np.float32]:
        """The bumper entry after this step's ``info`` (see the module docstring)."""
        if info is not None and info.get("collision", False):
            b = info.get("collision_bearing")
            known = b is not None and np.isfinite(b)
            self._touch = np.array([1.0, np.cos(b) if known else 0.0,
                                    np.sin(b) if known else 0.0], np.float32)
        else:
            self._touch[0] *= BUMPER_DECAY
        return self._touch.copy()


def status_one_hot(status: str | None) -> NDArray[np.float32]:
    """``status`` (one of ``BELIEF_STATUSES``; None: "tracking") as a one-hot vector."""
    status = "tracking" if status is None else status
    if status not in BELIEF_STATUSES:
        raise ValueError(f"status must be one of {BELIEF_STATUSES} or None, got {status!r}")
    one_hot = np.zeros(len(BELIEF_STATUSES), np.float32)
    one_hot[BELIEF_STATUSES.index(status)] = 1.0
    return one_hot


class NavigationObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Replace a belief observation by :class:`NavigationFeatures` (for RL policies).

    Parameters
    ----------
    env : gymnasium.Env
        An env whose observations are pose beliefs (``localization.wrappers``).
    lookaheads, replan_distance, status, bumper
        See :class:`NavigationFeatures`. The map is ``env.unwrapped.city``; the status is read
        from each reset's and step's ``info["belief_status"]`` (absent: "tracking"), the
        bumper from each step's ``info["collision"]`` and ``info["collision_bearing"]``.
    """

    def __init__(self, env: gym.Env, lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                 replan_distance: float = 1.0, status: bool = False,
                 bumper: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, lookaheads=lookaheads,
                                                 replan_distance=replan_distance, status=status,
                                                 bumper=bumper)
        gym.ObservationWrapper.__init__(self, env)
        self._status: str | None = None
        self._info: Mapping[str, Any] | None = None
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or not {"pose_mean", "pose_cov", "goal"} <= set(
                space.spaces):
            raise ValueError("NavigationObservation needs a belief observation space with keys "
                             f"pose_mean, pose_cov, goal; got {space}")
        self.features = NavigationFeatures(env.unwrapped.city, lookaheads, replan_distance,
                                           status, bumper)
        self.observation_space = self.features.observation_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
        """Reset the env and forget the plan."""
        self.features.reset()
        obs, info = self.env.reset(seed=seed, options=options)
        self._status, self._info = info.get("belief_status"), None
        return self.observation(obs), info

    def step(self, action: Any) -> tuple[dict[str, NDArray[np.float32]], SupportsFloat, bool,
                                         bool, dict[str, Any]]:
        """Step the env; the observation carries the step's belief status and contact."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._status, self._info = info.get("belief_status"), info
        return self.observation(obs), reward, terminated, truncated, info

    def observation(self, observation: Mapping[str, Any]) -> dict[str, NDArray[np.float32]]:
        """The policy observation for the belief observation (and the last status, contact)."""
        return self.features(observation, self._status, self._info)
