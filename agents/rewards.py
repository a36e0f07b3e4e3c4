"""Training reward for navigation: progress along the streets, not as the crow flies.

The env's reward counts progress in straight-line distance to the goal, which in a street
grid rewards cutting towards the goal through the blocks. :class:`StreetProgressReward`
replaces it, for training only, by progress in the street-path distance to the goal::

    reward = d(t-1) - d(t) - step_cost - collision_penalty * collision + success_bonus * success
             - uncertainty_penalty * max(0, log(sqrt(det P_xy)) - log(reference_std ** 2))

where ``d`` is the length of the shortest street path (:class:`agents.planner.StreetPlanner`)
from the robot to the goal. ``d`` uses the true pose in ``info["pose"]``: the reward is a
training signal computed by the simulator (privileged, like the env's own reward); the
policy's observation never contains the true pose. At the end of an episode ``info`` gets
``is_success`` (the goal was reached), which stable-baselines3's ``EvalCallback`` reports. A
kidnap (``info["kidnapped"]``, :class:`envs.kidnapping.KidnapWrapper`) is not progress: the
step that teleports the robot earns no progress term.

The last term (off by default: ``uncertainty_penalty=0``) is for active localization: it
charges the belief's position entropy above that of a ``reference_std`` (m) circle (up to a
constant, the entropy of a 2-D Gaussian is ``log sqrt(det P_xy)``), read from the
observation's ``pose_cov`` (the upper triangle of the 3 x 3 covariance), so the policy is
paid to keep the belief certain. It stays off because it did not help (issue 17, the agents
benchmark's comparison, held-out cities 21 and 22, 50 episodes per row, weight 0.01, both
policies at 100k steps): with a kidnap at step 50 of every episode 46 / 50 goals against the
plain reward's 45 / 50 (one episode) with a larger belief RMSE (2.51 m against 2.27 m) and
a longer path (28.2 m against 27.6 m); at night 0 / 50 with either (the daylight localizer is
lost: belief RMSE 10.9 m).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from agents.planner import StreetPlanner, path_length
from envs.datasets import check_city_env
from localization._validation import check_real

__all__ = ["StreetProgressReward", "position_entropy"]

_XX, _XY, _YY = 0, 1, 3  # pose_cov indices of the upper triangle (np.triu_indices(3))


def position_entropy(pose_cov: Any) -> float:
    """``log sqrt(det P_xy)`` of a pose covariance upper triangle (6,) (the entropy of the
    belief's 2-D position Gaussian up to a constant; -inf for a singular P_xy)."""
    c = np.asarray(pose_cov, float).ravel()
    if c.shape != (6,):
        raise ValueError(f"pose_cov must be the 6 upper-triangle entries, got shape {c.shape}")
    det = c[_XX] * c[_YY] - c[_XY] ** 2
    return 0.5 * float(np.log(det)) if det > 0 else -np.inf


class StreetProgressReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Reward progress along the shortest street path to the goal (see the module docstring).

    Parameters
    ----------
    env : gymnasium.Env — an AppearanceNav env (possibly wrapped); needs ``info["pose"]``,
        ``info["collision"]`` and ``env.unwrapped.goal``.
    step_cost, collision_penalty, success_bonus : float
    uncertainty_penalty : float — weight of the belief-entropy term (0: off); needs
        observations with ``pose_cov``.
    reference_std : float — position standard deviation (m) below which the belief is not
        charged.
    """

    def __init__(self, env: gym.Env, step_cost: float = 0.01, collision_penalty: float = 0.1,
                 success_bonus: float = 1.0, uncertainty_penalty: float = 0.0,
                 reference_std: float = 0.1) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, step_cost=step_cost,
                                                 collision_penalty=collision_penalty,
                                                 success_bonus=success_bonus,
                                                 uncertainty_penalty=uncertainty_penalty,
                                                 reference_std=reference_std)
        base = check_city_env(env)
        gym.Wrapper.__init__(self, env)
        self.planner = StreetPlanner(base.city)
        self.step_cost = check_real(step_cost, "step_cost", low=0.0)
        self.collision_penalty = check_real(collision_penalty, "collision_penalty", low=0.0)
        self.success_bonus = check_real(success_bonus, "success_bonus", low=0.0)
        self.uncertainty_penalty = check_real(uncertainty_penalty, "uncertainty_penalty",
                                              low=0.0)
        self.reference_std = check_real(reference_std, "reference_std", low=0.0, low_open=True)
        if self.uncertainty_penalty > 0 and not (
                isinstance(env.observation_space, gym.spaces.Dict)
                and "pose_cov" in env.observation_space.spaces):
            raise ValueError("uncertainty_penalty > 0 needs belief observations with pose_cov, "
                             f"got {env.observation_space}")
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
        progress = 0.0 if info.get("kidnapped", False) else self._distance - distance
        reward = (progress - self.step_cost
                  - self.collision_penalty * float(info["collision"])
                  + self.success_bonus * float(terminated))
        if self.uncertainty_penalty > 0:
            excess = position_entropy(obs["pose_cov"]) - np.log(self.reference_std ** 2)
            reward -= self.uncertainty_penalty * max(0.0, excess)
            info["uncertainty_excess"] = max(0.0, excess)
        self._distance = distance
        info["street_distance"] = distance
        if terminated or truncated:
            info["is_success"] = bool(terminated)  # read by stable-baselines3's EvalCallback
        return obs, reward, terminated, truncated, info
