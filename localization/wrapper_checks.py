"""Checks of :class:`~localization.wrappers.BeliefWrapper`'s arguments: the localizer against
the env it wraps, and the options that need a single map."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from localization.districts import DistrictLocalizer
from localization.localizer import AppearanceLocalizer

__all__ = ["check_compatible", "single_map"]


def check_compatible(env: gym.Env, localizer: AppearanceLocalizer | DistrictLocalizer) -> None:
    """A TypeError / ValueError unless ``localizer`` is fitted for ``env``'s image size and
    camera (BeliefWrapper's check)."""
    if not isinstance(localizer, (AppearanceLocalizer, DistrictLocalizer)):
        raise TypeError("localizer must be a fitted AppearanceLocalizer or "
                        f"DistrictLocalizer, got {type(localizer).__name__}")
    localizer.check_ready()
    image_shape = tuple(env.observation_space["image"].shape[:2])
    if image_shape != tuple(localizer.image_size_):
        raise ValueError(f"the localizer was fitted on {tuple(localizer.image_size_)} "
                         f"images but the env renders {image_shape}")
    camera = getattr(env.unwrapped, "camera_name", None)
    if localizer.camera_ is not None and camera is not None and camera != localizer.camera_:
        raise ValueError(f"the localizer was fitted for camera {localizer.camera_!r} "
                         f"but the env uses {camera!r}")


def single_map(localizer: Any, option: str) -> AppearanceLocalizer:
    """``localizer`` if it is one map (an AppearanceLocalizer), else a TypeError naming the
    option that needs one."""
    if not isinstance(localizer, AppearanceLocalizer):
        raise TypeError(f"{option} needs an AppearanceLocalizer (one map), got "
                        f"{type(localizer).__name__}")
    return localizer
