"""Run navigation episodes and measure them: success, path-length ratio, collisions, time.

Works with any agent that has ``reset()`` and ``act(obs)`` (or ``act(obs, info)``: it then
gets the step's info, e.g. ``belief_status``) on belief observations and any env
whose ``info`` carries the true pose (``AppearanceNav-v0`` under a pose source from
``localization.wrappers``). The true pose is used here for scoring only.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from agents.planner import StreetPlanner, path_length

__all__ = ["Episode", "run_episode", "run_episodes", "summarize"]


@dataclass(frozen=True)
class Episode:
    """One scored episode.

    Attributes
    ----------
    seed : int — the reset seed (start pose and goal).
    success : bool — the robot reached the goal (the env terminated).
    steps : int — env steps taken.
    time : float — seconds of simulated time (steps x dt).
    path_length : float — distance (m) the robot actually travelled.
    shortest : float — length (m) of the shortest street path from the start to the goal, less
        the goal radius (the episode ends that close to the goal).
    collision_steps : int — steps in which the robot touched a building or the boundary.
    final_distance : float — distance (m) to the goal at the end.
    belief_rmse : float — RMS distance (m) between the belief mean and the true position.
    """

    seed: int
    success: bool
    steps: int
    time: float
    path_length: float
    shortest: float
    collision_steps: int
    final_distance: float
    belief_rmse: float

    @property
    def path_ratio(self) -> float:
        """Travelled / shortest street path length."""
        return self.path_length / max(self.shortest, 1e-9)


def run_episode(env: gym.Env, agent: Any, seed: int, planner: StreetPlanner | None = None,
                max_steps: int | None = None, options: dict[str, Any] | None = None) -> Episode:
    """Run one episode of ``agent`` on ``env`` from ``env.reset(seed=seed, options=options)``
    and score it."""
    base = env.unwrapped
    planner = planner or StreetPlanner(base.city)
    obs, info = env.reset(seed=seed, options=options)
    agent.reset()
    reads_info = "info" in inspect.signature(agent.act).parameters  # e.g. belief_status
    start = info["pose"].copy()
    shortest = max(path_length(planner.plan(start[:2], base.goal)) - base.GOAL_RADIUS, 0.0)
    travelled, collisions, sq_err, steps = 0.0, 0, [], 0
    terminated = truncated = False
    prev = start[:2]
    while not (terminated or truncated) and (max_steps is None or steps < max_steps):
        action = agent.act(obs, info) if reads_info else agent.act(obs)
        obs, _, terminated, truncated, info = env.step(action)
        pose = info["pose"]
        travelled += float(np.hypot(*(pose[:2] - prev)))
        prev = pose[:2]
        collisions += bool(info["collision"])
        sq_err.append(float(np.sum((np.asarray(obs["pose_mean"][:2], float) - pose[:2]) ** 2))
                      if "pose_mean" in obs else np.nan)
        steps += 1
    return Episode(seed=int(seed), success=bool(terminated), steps=steps, time=steps * base.dt,
                   path_length=travelled, shortest=shortest, collision_steps=collisions,
                   final_distance=float(info["distance_to_goal"]),
                   belief_rmse=float(np.sqrt(np.mean(sq_err))) if sq_err else np.nan)


def run_episodes(env: gym.Env, agent: Any, seeds: Iterable[int], progress: bool = True,
                 desc: str = "episodes", max_steps: int | None = None,
                 options: Callable[[int], dict[str, Any] | None] | None = None,
                 ) -> list[Episode]:
    """:func:`run_episode` for each seed (a progress bar when ``progress``); ``options(seed)``
    gives each reset's options (e.g. a start pose), None the env's random start."""
    planner = StreetPlanner(env.unwrapped.city)
    seeds = list(seeds)
    return [run_episode(env, agent, s, planner, max_steps, options(s) if options else None)
            for s in tqdm(seeds, desc=desc, disable=not progress, leave=False)]


def summarize(episodes: Sequence[Episode]) -> dict[str, float]:
    """Success rate, mean path ratio and time to goal (successes), collision rates, belief error."""
    if not episodes:
        raise ValueError("no episodes to summarize")
    ok = [e for e in episodes if e.success]
    return {
        "episodes": len(episodes),
        "success_rate": len(ok) / len(episodes),
        "path_ratio": float(np.mean([e.path_ratio for e in ok])) if ok else float("nan"),
        "time_to_goal": float(np.mean([e.time for e in ok])) if ok else float("nan"),
        "collision_episodes": float(np.mean([e.collision_steps > 0 for e in episodes])),
        "collisions_per_episode": float(np.mean([e.collision_steps for e in episodes])),
        "belief_rmse": float(np.sqrt(np.nanmean([e.belief_rmse ** 2 for e in episodes]))),
    }


def as_records(episodes: Sequence[Episode]) -> list[dict[str, Any]]:
    """Episodes as JSON-ready dicts (with the path ratio)."""
    return [{**asdict(e), "path_ratio": e.path_ratio} for e in episodes]
