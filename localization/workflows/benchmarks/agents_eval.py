"""Episodes of the agents benchmark (:mod:`.agents`): one navigator on one pose source in one
city under one condition, split by reset seed into tasks for
:func:`~localization.workflows.parallel.map_tasks`.

Each worker loads a city's localizer once and keeps its env while the next task shares it
(:func:`~localization.workflows.parallel.worker_env`); an episode
depends only on its reset seed, so a split run gives the serial run's records. Every row of a
comparison runs the same seeds, so the oracle and belief rows (and the plain and active
rows) start from the same poses with the same goals.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from agents.evaluation import Episode, run_episodes, summarize
from agents.ppo import PPOAgent
from agents.scripted import ScriptedAgent
from agents.sources import make_pose_env
from localization.loading import load_localizer
from localization.localizer import AppearanceLocalizer
from localization.workflows.parallel import worker_env

__all__ = ["EpisodeTask", "localizer_path", "run_episode_task", "summarize_row"]


def localizer_path(folder: str | Path, city: int) -> Path:
    """The street-surface localizer file of ``city`` in ``folder``."""
    return Path(folder) / f"city_{int(city)}.npz"


@dataclass(frozen=True)
class EpisodeTask:
    """Episodes of one navigator on one source.

    Attributes
    ----------
    agent : "scripted" or the path of a saved PPO policy (``policy.pt``).
    source : "oracle" or "belief".
    city : the held-out city (scene seed).
    localizers : folder of the cities' localizers (:func:`localizer_path`).
    seeds : the reset seeds.
    kidnap_at : steps of each episode that start with a kidnap.
    conditions : the env's look ("" : default; e.g. "night").
    detect_divergence : the belief's EKF notices when it is lost (method §13.1).
    motion_noise, start : env settings.
    """

    agent: str
    source: str
    city: int
    localizers: str
    seeds: tuple[int, ...]
    kidnap_at: tuple[int, ...] = ()
    conditions: str = ""
    detect_divergence: bool = True
    motion_noise: float = 0.1
    start: str = "random"

    def env_key(self) -> tuple[Any, ...]:
        """What the env depends on (the cache key of this worker's envs)."""
        return (self.source, self.city, self.localizers, self.kidnap_at, self.conditions,
                self.detect_divergence, self.motion_noise, self.start)


_LOCALIZERS: dict[Path, AppearanceLocalizer] = {}


def _env(task: EpisodeTask) -> Any:
    """This process's env for ``task`` (:func:`~localization.workflows.parallel.worker_env`)."""
    return worker_env(task.env_key(), lambda: _make_env(task))


def _make_env(task: EpisodeTask) -> Any:
    """The pose env of ``task``."""
    belief: dict[str, Any] = {}
    localizer = None
    if task.source == "belief":
        path = localizer_path(task.localizers, task.city)
        if path not in _LOCALIZERS:
            _LOCALIZERS[path] = load_localizer(path)
        localizer = _LOCALIZERS[path]
        if task.detect_divergence:
            belief["filter_options"] = {"detect_divergence": True}
    return make_pose_env(task.source, localizer, scene_seed=task.city,
                         motion_noise=task.motion_noise, start=task.start,
                         kidnap_at=task.kidnap_at, conditions=task.conditions or None, **belief)


def run_episode_task(task: EpisodeTask) -> tuple[list[Episode], float]:
    """Run the task's episodes: (episodes, seconds)."""
    t0 = time.perf_counter()
    env = _env(task)
    city = env.unwrapped.city
    agent = ScriptedAgent(city) if task.agent == "scripted" else PPOAgent.load(task.agent, city)
    episodes = run_episodes(env, agent, task.seeds, progress=False)
    return episodes, time.perf_counter() - t0


def summarize_row(name: str, episodes: list[Episode], seconds: float) -> dict[str, Any]:
    """One table row: :func:`agents.evaluation.summarize` plus the mean path length (m) of the
    successes and the wall seconds."""
    ok = [e.path_length for e in episodes if e.success]
    return {"row": name, **summarize(episodes),
            "path_length": float(sum(ok) / len(ok)) if ok else float("nan"),
            "wall_seconds": round(seconds, 1)}
