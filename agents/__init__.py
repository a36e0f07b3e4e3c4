"""Agents that navigate on a pose belief: a street planner, a scripted pure-pursuit agent,
PPO (stable-baselines3) on belief observations, rewards, pose sources and evaluation.

Names load on first use (stable-baselines3 and torch only for the PPO names).
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "StreetPlanner": "planner", "PlannedPath": "planner", "path_length": "planner",
    "ScriptedAgent": "scripted", "Navigator": "scripted", "pure_pursuit": "scripted",
    "check_belief_observation": "scripted",
    "NavigationObservation": "observations", "NavigationFeatures": "observations",
    "StreetProgressReward": "rewards",
    "PPOAgent": "ppo", "make_ppo": "ppo", "save_policy": "ppo", "load_policy": "ppo",
    "POSE_SOURCES": "sources", "make_pose_env": "sources", "LaneStart": "sources",
    "Episode": "evaluation", "run_episode": "evaluation", "run_episodes": "evaluation",
    "summarize": "evaluation",
}
__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
