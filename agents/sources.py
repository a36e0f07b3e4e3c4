"""The three pose sources agents are compared on, as ready-made envs.

``make_pose_env(source, ...)`` builds ``AppearanceNav-v0`` wrapped in one of

- ``"oracle"``: :class:`localization.wrappers.OracleWrapper` — the true pose (an upper bound);
- ``"belief"``: :class:`localization.wrappers.BeliefWrapper` — the GSE/EKF belief from images;
- ``"dead_reckoning"``: :class:`localization.wrappers.DeadReckoningWrapper` — the motion model F
  alone from the true start pose,

all with the same observation ``Dict(pose_mean=(3,), pose_cov=(6,), goal=(2,))``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

import envs  # noqa: F401  (registers AppearanceNav-v0)
from localization.wrappers import BeliefWrapper, DeadReckoningWrapper, OracleWrapper

__all__ = ["POSE_SOURCES", "make_pose_env"]

POSE_SOURCES = ("oracle", "belief", "dead_reckoning")


def make_pose_env(source: str, localizer: Any = None, *, measurement: str | None = None,
                  scene_seed: int = 0, camera: str = "perspective",
                  image_size: tuple[int, int] = (64, 64), motion_noise: float = 0.05,
                  max_episode_steps: int = 400, **belief_kwargs: Any) -> gym.Env:
    """``AppearanceNav-v0`` with the named pose source (see the module docstring).

    Parameters
    ----------
    source : {"oracle", "belief", "dead_reckoning"}
    localizer : AppearanceLocalizer, optional
        Fitted for this city, camera and image size, with its process noise; needed by
        "belief" (the measurement maps and Q) and "dead_reckoning" (Q).
    measurement : str, optional
        The belief's measurement model (default: BeliefWrapper's).
    scene_seed, camera, image_size, motion_noise, max_episode_steps
        Passed to ``gymnasium.make("AppearanceNav-v0", ...)``.
    **belief_kwargs
        More BeliefWrapper settings (``gate_probability``, ``relocalize_after``, ...).
    """
    if source not in POSE_SOURCES:
        raise ValueError(f"unknown pose source {source!r}; choose one of {POSE_SOURCES}")
    if source != "oracle" and localizer is None:
        raise ValueError(f"pose source {source!r} needs a fitted localizer")
    env = gym.make("AppearanceNav-v0", scene_seed=scene_seed, camera=camera,
                   image_size=tuple(image_size), motion_noise=motion_noise,
                   max_episode_steps=max_episode_steps)
    if source == "oracle":
        return OracleWrapper(env)
    if source == "dead_reckoning":
        return DeadReckoningWrapper(env, localizer.process_noise_body_)
    if measurement is not None:
        belief_kwargs["measurement"] = measurement
    return BeliefWrapper(env, localizer, **belief_kwargs)
