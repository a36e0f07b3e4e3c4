"""Episode time limits that grow with the city: ``gymnasium.make("AppearanceNav-v0")``'s
truncation.

A fixed limit cannot serve every city: the default 20 m city's 500 steps (50 s) let the
scripted agent reach its farthest goal (about 36 m of streets, ~450 steps at 0.9 m/s), but on
a 60 m city a goal across the city is 116 m of streets away (1355 steps measured on city 0)
and 500 steps cut most far episodes short. So ``AppearanceNav-v0`` is registered without a
fixed ``max_episode_steps``; :class:`CityTimeLimit` (the spec's additional wrapper) truncates
after :func:`episode_steps` of the env's city side: 25 steps per metre, 500 for the default
city as before, 1500 for a 60 m city.

``gymnasium.make(..., max_episode_steps=N)`` keeps its usual meaning: gymnasium adds its own
``TimeLimit(N)`` and :class:`CityTimeLimit` then truncates nothing. One difference from
gymnasium's convention: ``max_episode_steps=-1`` (no ``TimeLimit``) still gets the city's
limit, since it cannot be told from no argument; make ``AppearanceNavEnv`` directly (or pass
a large N) for episodes without one.
"""

from __future__ import annotations

import math
from copy import deepcopy
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec
from gymnasium.wrappers import TimeLimit

from localization._validation import check_real

__all__ = ["STEPS_PER_METRE", "CityTimeLimit", "episode_steps"]

#: episode steps per metre of city side (500 for the default 20 m city)
STEPS_PER_METRE = 25.0


def episode_steps(city_size: float) -> int:
    """The default episode limit (steps) of a city of side ``city_size`` metres:
    ``ceil(STEPS_PER_METRE * city_size)`` (500 at 20 m, 1500 at 60 m).

    Raises
    ------
    ValueError
        If ``city_size`` is not a positive finite number.
    """
    size = check_real(city_size, "city_size", low=0.0, low_open=True)
    return math.ceil(STEPS_PER_METRE * size - 1e-9)


def _has_time_limit(env: gym.Env) -> bool:
    """Whether a gymnasium ``TimeLimit`` is among the wrappers of ``env``."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, TimeLimit):
            return True
        env = env.env
    return False


class CityTimeLimit(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Truncate an ``AppearanceNav-v0`` episode after :func:`episode_steps` of its city, unless
    a ``TimeLimit`` below already limits it (``gymnasium.make(..., max_episode_steps=N)``).

    Attributes
    ----------
    max_episode_steps : int or None
        The limit this wrapper applies (None: it defers to the ``TimeLimit`` below).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        city = getattr(env.unwrapped, "city", None)
        if city is None:
            raise TypeError(f"CityTimeLimit wraps an AppearanceNav env (with a city), got "
                            f"{type(env.unwrapped).__name__}")
        self.max_episode_steps: int | None = (None if _has_time_limit(env)
                                              else episode_steps(city.size))
        self._elapsed_steps = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        """Reset the env and the step count."""
        self._elapsed_steps = 0
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Step the env; ``truncated`` once :attr:`max_episode_steps` steps are done."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._elapsed_steps += 1
        if self.max_episode_steps is not None and self._elapsed_steps >= self.max_episode_steps:
            truncated = True
        return obs, reward, terminated, truncated, info

    @property
    def spec(self) -> EnvSpec | None:
        """The env's spec with ``max_episode_steps`` set to this wrapper's limit (as
        gymnasium's ``TimeLimit`` does), or the inner spec when it defers."""
        spec = self.env.spec
        if spec is None or self.max_episode_steps is None:
            return spec
        spec = deepcopy(spec)
        spec.max_episode_steps = self.max_episode_steps
        return spec
