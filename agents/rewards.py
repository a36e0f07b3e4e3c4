"""Training reward for navigation: progress along the streets, not as the crow flies.

The env's reward counts progress in straight-line distance to the goal, which in a street
grid rewards cutting towards the goal through the blocks. :class:`StreetProgressReward`
replaces it, for training only, by progress in the street-path distance to the goal::

    reward = d(t-1) - d(t) - step_cost - collision_penalty * collision + success_bonus * success

where ``d`` is the length of the shortest street path (:class:`agents.planner.StreetPlanner`)
from the robot to the goal. ``d`` uses the true pose in ``info["pose"]``: the reward is a
training signal computed by the simulator (privileged, like the env's own reward); the
policy's observation never contains the true pose. At the end of an episode ``info`` gets
``is_success`` (the goal was reached), which stable-baselines3's ``EvalCallback`` reports.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from agents.planner import StreetPlanner, path_length
from envs.datasets import check_city_env
from localization._validation import check_real

__all__ = ["StreetProgressReward"]


class StreetProgressReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Reward progress along the shortest street path to the goal (see the module docstring).

    Parameters
    ----------
    env : gymnasium.Env — an AppearanceNav env (possibly wrapped); needs ``info["pose"]``,
        ``info["collision"]`` and ``env.unwrapped.goal``.
    step_cost, collision_penalty, success_bonus : float
    """

    def __init__(self, env: gym.Env, step_cost: float = 0.01, collision_penalty: float = 0.1,
                 success_bonus: float = 1.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, step_cost=step_cost,
                                                 collision_penalty=collision_penalty,
                                                 success_bonus=success_bonus)
        base = check_city_env(env)
        gym.Wrapper.__init__(self, env)
        self.planner = StreetPlanner(base.city)
        self.step_cost = check_real(step_cost, "step_cost", low=0.0)
        self.collision_penalty = check_real(collision_penalty, "collision_penalty", low=0.0)
        self.success_bonus = check_real(success_bonus, "success_bonus", low=0.0)
        self._distance = 0.0

    def street_distance(self, pose: np.ndarray) -> float:
        """Length (m) of the shortest street path from ``pose`` to the goal."""
        goal = self.env.unwrapped.goal
        return path_length(self.planner.plan(pose[:2], goal))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._distance = self.street_distance(info["pose"])
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, _, terminated, truncated, info = self.env.step(action)
        distance = self.street_distance(info["pose"])
        reward = (self._distance - distance - self.step_cost
                  - self.collision_penalty * float(info["collision"])
                  + self.success_bonus * float(terminated))
        self._distance = distance
        info["street_distance"] = distance
        if terminated or truncated:
            info["is_success"] = bool(terminated)  # read by stable-baselines3's EvalCallback
        return obs, reward, terminated, truncated, info
