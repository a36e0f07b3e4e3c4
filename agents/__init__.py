"""Agents that navigate on a pose belief: a street planner, a scripted pure-pursuit agent,
PPO (stable-baselines3) on belief observations, rewards, pose sources and evaluation.

Names load on first use (stable-baselines3 and torch only for the PPO names).
"""

from __future__ import annotations

from localization._lazy import lazy_names

_LAZY = {
    "StreetPlanner": "planner", "PlannedPath": "planner", "path_length": "planner",
    "ScriptedAgent": "scripted", "Navigator": "scripted", "pure_pursuit": "scripted",
    "Recovery": "recovery",
    "check_belief_observation": "scripted",
    "NavigationObservation": "observations", "NavigationFeatures": "observations",
    "StreetProgressReward": "rewards",
    "PPOAgent": "ppo", "make_ppo": "ppo", "save_policy": "ppo", "load_policy": "ppo",
    "POSE_SOURCES": "sources", "make_pose_env": "sources", "LaneStart": "sources",
    "Episode": "evaluation", "run_episode": "evaluation", "run_episodes": "evaluation",
    "summarize": "evaluation", "spl": "evaluation",
}
__all__ = [
    "POSE_SOURCES",
    "Episode",
    "LaneStart",
    "NavigationFeatures",
    "NavigationObservation",
    "Navigator",
    "PPOAgent",
    "PlannedPath",
    "Recovery",
    "ScriptedAgent",
    "StreetPlanner",
    "StreetProgressReward",
    "check_belief_observation",
    "load_policy",
    "make_pose_env",
    "make_ppo",
    "path_length",
    "pure_pursuit",
    "run_episode",
    "run_episodes",
    "save_policy",
    "spl",
    "summarize",
]

__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals())
