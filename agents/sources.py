"""The three pose sources agents are compared on, as ready-made envs.

``make_pose_env(source, ...)`` builds ``AppearanceNav-v0`` wrapped in one of

- ``"oracle"``: :class:`localization.wrappers.OracleWrapper` — the true pose (an upper bound);
- ``"belief"``: :class:`localization.wrappers.BeliefWrapper` — the GSE belief from images, with
  ``filter="ekf"`` (default) or ``filter="particles"`` (and ``filter_options``): one source
  with a choice of filter rather than a source per filter, since both give the same
  observation and ``info["belief_status"]``;
- ``"dead_reckoning"``: :class:`localization.wrappers.DeadReckoningWrapper` — the motion model F
  alone from the true start pose,

all with the same observation ``Dict(pose_mean=(3,), pose_cov=(6,), goal=(2,))``.

Episodes start on a street lane by default (:class:`LaneStart`: like a parked car, on a street
and facing along it), which is where the localizer is trained (``envs.lanes``);
``start="random"`` keeps the env's own start (any free pose, any heading).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers AppearanceNav-v0)
from envs.appearance_nav import RESET_OPTIONS
from envs.cameras import check_image_size
from envs.datasets import check_city_env
from envs.kidnapping import KidnapWrapper
from envs.lanes import lane_poses
from localization._validation import check_choice, check_options, check_real, check_seed
from localization.wrappers import BeliefWrapper, DeadReckoningWrapper, OracleWrapper

__all__ = ["AGENT_STEPS_PER_METRE", "POSE_SOURCES", "STARTS", "LaneStart", "agent_episode_steps",
           "make_pose_env"]

POSE_SOURCES = ("oracle", "belief", "dead_reckoning")
STARTS = ("lane", "random")
#: the agents' default episode limit per metre of city side (400 steps in the default city)
AGENT_STEPS_PER_METRE = 20.0


def agent_episode_steps(city_size: float) -> int:
    """The agents' default episode limit: ``round(AGENT_STEPS_PER_METRE * city_size)`` steps
    (400 for the default 20 m city, 1200 for a 60 m one)."""
    return max(1, round(AGENT_STEPS_PER_METRE * check_real(city_size, "city_size", low=0.0,
                                                           low_open=True)))


class LaneStart(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Start every episode on a street lane: a pose from ``envs.lanes.lane_poses`` (any street,
    either direction, or a turn), unless ``options["pose"]`` is given.

    The start pose is drawn from ``default_rng(seed)`` at a seeded reset, else from a generator
    seeded at the last seeded reset, so seeds give the same episodes.

    Parameters
    ----------
    env : an AppearanceNav env.
    lateral, heading : float — largest offsets from the lane (m, rad).
    """

    def __init__(self, env: gym.Env, lateral: float = 0.2, heading: float = 0.1) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, lateral=lateral, heading=heading)
        check_city_env(env)
        gym.Wrapper.__init__(self, env)
        self.lateral = check_real(lateral, "lateral", low=0.0)
        self.heading = check_real(heading, "heading", low=0.0)
        self._rng = np.random.default_rng()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None,
              ) -> tuple[Any, dict[str, Any]]:
        if check_seed(seed, "seed", optional=True) is not None:
            self._rng = np.random.default_rng(seed)
        options = check_options(options, "options", RESET_OPTIONS)
        if options.get("pose") is None:
            poses, _ = lane_poses(self.env.unwrapped.city, 1, self._rng, "streets",
                                  lateral=self.lateral, heading=self.heading)
            options["pose"] = poses[0]
        return self.env.reset(seed=seed, options=options)


def make_pose_env(source: str, localizer: Any = None, *, measurement: str | None = None,
                  scene_seed: int = 0, camera: str = "perspective",
                  image_size: tuple[int, int] = (64, 64), motion_noise: float = 0.1,
                  max_episode_steps: int | None = None, start: str = "lane",
                  kidnap_at: tuple[int, ...] = (), kidnap_push: tuple[float, float] | None = None,
                  city_layout: str = "random", city_size: float = 20.0, conditions: Any = None,
                  **belief_kwargs: Any) -> gym.Env:
    """``AppearanceNav-v0`` with the named pose source (see the module docstring).

    Parameters
    ----------
    source : {"oracle", "belief", "dead_reckoning"}
    localizer : AppearanceLocalizer, optional
        Fitted for this city, camera and image size, with its process noise; needed by
        "belief" (the measurement maps and Q) and "dead_reckoning" (Q).
    measurement : str, optional
        The belief's measurement model (default: BeliefWrapper's).
    scene_seed, camera, image_size, motion_noise, city_size
        Passed to ``gymnasium.make("AppearanceNav-v0", ...)``; the localizer's noise model
        holds for the motion noise it was fitted with (0.1 in ``make demo``).
    max_episode_steps : int, optional
        Episode truncation; default :data:`AGENT_STEPS_PER_METRE` per metre of city side
        (400 for the default 20 m city, 1200 for a 60 m one).
    start : {"lane", "random"}
        Start episodes on a street lane (:class:`LaneStart`) or anywhere free (the env's own).
    kidnap_at : tuple of int
        Steps of each episode that start with a kidnap (:class:`envs.kidnapping.KidnapWrapper`
        under the pose source, seeded by the reset seed: no pose source is told).
    kidnap_push : (float, float), optional
        Make each kidnap a sideways shove by a distance in this range (m) instead of a
        teleport (``KidnapWrapper(push=...)``, e.g. ``envs.kidnapping.PUSH_DISTANCE``).
    city_layout : {"random", "lookalike"}
        The env's city layout.
    conditions : str or dict, optional
        The env's appearance conditions (a preset name such as "night" or "traffic",
        "random", or a dict; see ``envs.conditions``); None: the env's default look.
    **belief_kwargs
        More BeliefWrapper settings (``filter``, ``filter_options``, ``gate_probability``,
        ``relocalize_after``, ...).
    """
    check_choice(source, "pose source", POSE_SOURCES)
    check_choice(start, "start", STARTS)
    if source != "oracle":
        _check_localizer(localizer, source)
    if belief_kwargs and source != "belief":
        raise ValueError(f"belief settings {sorted(belief_kwargs)} apply to source 'belief' only")
    if max_episode_steps is None:
        max_episode_steps = agent_episode_steps(city_size)
    env = gym.make("AppearanceNav-v0", scene_seed=scene_seed, camera=camera,
                   image_size=check_image_size(image_size), motion_noise=motion_noise,
                   max_episode_steps=max_episode_steps, city_layout=city_layout,
                   city_size=city_size,
                   **({} if conditions is None else {"conditions": conditions}))
    if start == "lane":
        env = LaneStart(env)
    if kidnap_push is not None and not kidnap_at:
        raise ValueError("kidnap_push shapes the kidnaps of kidnap_at: give kidnap_at too")
    if kidnap_at:
        env = KidnapWrapper(env, at_steps=kidnap_at, push=kidnap_push)
    if source == "oracle":
        return OracleWrapper(env)
    if source == "dead_reckoning":
        return DeadReckoningWrapper(env, localizer.process_noise_body_)
    if measurement is not None:
        belief_kwargs["measurement"] = measurement
    return BeliefWrapper(env, localizer, **belief_kwargs)


def _check_localizer(localizer: Any, source: str) -> None:
    """The belief and dead-reckoning sources need a fitted localizer with its process noise."""
    if localizer is None:
        raise ValueError(f"pose source {source!r} needs a fitted localizer (localizer=None)")
    if getattr(localizer, "process_noise_body_", None) is None:
        raise ValueError(f"localizer must be a fitted AppearanceLocalizer with its process noise "
                         f"(fit_process_noise), got {type(localizer).__name__}")
