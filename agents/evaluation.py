"""Run navigation episodes and measure them with the embodied-navigation field's metrics.

Every summary reports, each with its standard error: success, SPL (success weighted by path
length, Anderson et al. 2018, "On Evaluation of Embodied Navigation Agents", with the
shortest street path as the reference), collisions per episode, time to goal and the belief's
RMSE; and, for a belief that names its status, how often it misled: steps on which it said
"tracking" while more than :data:`MISLEADING_ERROR` m off (GNSS integrity monitoring's
"hazardously misleading information": a wrong pose given as good, which a pilot that reads the
status cannot guard against).

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

__all__ = ["METRIC_COLUMNS", "MISLEADING_ERROR", "Episode", "as_records", "mean_and_se",
           "metric_cells", "run_episode", "run_episodes", "spl", "summarize"]

#: m: a step on which the belief says "tracking" while its mean is farther than this from the
#: true position misleads (a street of the 20 m city is 3 m wide: 1 m off puts a plan at a wall)
MISLEADING_ERROR = 1.0


@dataclass(frozen=True)
class Episode:
    """One scored episode.

    Attributes
    ----------
    seed : int — the reset seed (start pose and goal).
    success : bool — the robot reached the goal (the env terminated).
    steps : int — env steps taken.
    time : float — seconds of simulated time (steps x dt).
    path_length : float — distance (m) the robot actually drove (a kidnap's teleport, flagged
        by ``info["kidnapped"]``, is not counted).
    shortest : float — length (m) of the shortest street path from the start to the goal, less
        the goal radius (the episode ends that close to the goal).
    collision_steps : int — steps in which the robot touched anything (a building, the
        boundary or a moving object).
    final_distance : float — distance (m) to the goal at the end.
    belief_rmse : float — RMS distance (m) between the belief mean and the true position.
    traffic_collision_steps : int — of ``collision_steps``, those that touched a moving object
        (``"traffic"`` in ``info["collision_with"]``): hazards an agent may not be able to avoid.
    tipped_over : bool — the robot was on its side or back at some step
        (``info["tipped_over"]``: a moving object flipped it; it then drives blind).
    misled_steps : int or None — steps on which ``info["belief_status"]`` was "tracking" while
        the belief mean was more than :data:`MISLEADING_ERROR` m from the true position; None
        for a pose source that names no status (the true pose, dead reckoning) and for
        records written before it was measured.
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
    traffic_collision_steps: int = 0
    tipped_over: bool = False
    misled_steps: int | None = None

    @property
    def path_ratio(self) -> float:
        """Travelled / shortest street path length."""
        return self.path_length / max(self.shortest, 1e-9)

    @property
    def spl(self) -> float:
        """This episode's term of SPL: ``success * shortest / max(path_length, shortest)``."""
        return spl([self.success], [self.shortest], [self.path_length])


def spl(success: Sequence[bool], shortest: Sequence[float], path_length: Sequence[float]
        ) -> float:
    """Success weighted by (normalised inverse) path length (Anderson et al. 2018)::

        SPL = 1/N sum_i S_i * l_i / max(p_i, l_i)

    Parameters
    ----------
    success : (N,) bool — S_i, the episode reached its goal.
    shortest : (N,) float — l_i, the shortest path length (m) from the start to the goal.
    path_length : (N,) float — p_i, the length (m) the agent travelled.

    Returns
    -------
    float in [0, 1]. An episode whose start is already at the goal (l_i = 0) scores S_i.

    Raises
    ------
    ValueError
        If the three have different lengths, are empty, or hold negative or non-finite lengths.
    """
    s = np.asarray(success, dtype=bool)
    lengths = [np.asarray(v, dtype=np.float64) for v in (shortest, path_length)]
    if s.ndim != 1 or len(s) == 0 or any(v.shape != s.shape for v in lengths):
        raise ValueError(f"success, shortest and path_length must be 1-D of one non-zero length, "
                         f"got shapes {s.shape}, {lengths[0].shape}, {lengths[1].shape}")
    for name, v in zip(("shortest", "path_length"), lengths):
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ValueError(f"{name} must hold finite lengths >= 0, got {v}")
    l, p = lengths
    ratio = np.divide(l, np.maximum(p, l), out=np.ones_like(l), where=np.maximum(p, l) > 0)
    return float(np.mean(s * ratio))


def mean_and_se(values: Sequence[float]) -> tuple[float, float]:
    """The mean of ``values`` and its standard error ``std / sqrt(n)`` (NaN for an empty
    sequence; 0 standard error for one value)."""
    v = np.asarray(values, dtype=np.float64)
    if len(v) == 0:
        return float("nan"), float("nan")
    se = float(np.std(v, ddof=1) / np.sqrt(len(v))) if len(v) > 1 else 0.0
    return float(np.mean(v)), se


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
    travelled, collisions, traffic, sq_err, steps, tipped = 0.0, 0, 0, [], 0, False
    misled: int | None = None
    terminated = truncated = False
    prev = start[:2]
    while not (terminated or truncated) and (max_steps is None or steps < max_steps):
        action = agent.act(obs, info) if reads_info else agent.act(obs)
        obs, _, terminated, truncated, info = env.step(action)
        pose = info["pose"]
        if not info.get("kidnapped", False):  # a teleport is not driven
            travelled += float(np.hypot(*(pose[:2] - prev)))
        prev = pose[:2]
        collisions += bool(info["collision"])
        traffic += "traffic" in info.get("collision_with", ())
        tipped = tipped or bool(info.get("tipped_over", False))
        sq_err.append(float(np.sum((np.asarray(obs["pose_mean"][:2], float) - pose[:2]) ** 2))
                      if "pose_mean" in obs else np.nan)
        if "belief_status" in info:
            misled = (misled or 0) + _misleads(info["belief_status"], sq_err[-1])
        steps += 1
    return Episode(seed=int(seed), success=bool(terminated), steps=steps, time=steps * base.dt,
                   path_length=travelled, shortest=shortest, collision_steps=collisions,
                   final_distance=float(info["distance_to_goal"]),
                   belief_rmse=float(np.sqrt(np.mean(sq_err))) if sq_err else np.nan,
                   traffic_collision_steps=traffic, tipped_over=tipped, misled_steps=misled)


def _misleads(status: str, squared_error: float) -> bool:
    """The belief says "tracking" while more than :data:`MISLEADING_ERROR` m off."""
    return status == "tracking" and squared_error > MISLEADING_ERROR ** 2


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
    """The navigation metrics of ``episodes``, each ``<name>`` with its standard error
    ``<name>_se``.

    Returns
    -------
    dict with ``episodes``; ``success_rate`` (binomial standard error); ``spl`` (see
    :func:`spl`); ``collisions_per_episode`` (steps in contact; ``traffic_collisions_per_episode``
    those with a moving object); ``collision_episodes``
    (share of episodes with any contact); ``tipped_over_episodes`` (share of episodes in
    which the robot was flipped over); ``time_to_goal`` (simulated s) and ``path_ratio``
    (travelled / shortest), over successes; ``belief_rmse`` (m, over every step of every
    episode, its standard error by the delta method from the episodes' mean squared errors);
    ``misled_steps_per_episode`` and ``misled_episodes`` (share of episodes with any), over the
    episodes that measured it (NaN when none did).
    """
    if not episodes:
        raise ValueError("no episodes to summarize")
    n = len(episodes)
    ok = [e for e in episodes if e.success]
    p = len(ok) / n
    misled = [e.misled_steps for e in episodes if e.misled_steps is not None]
    out: dict[str, float] = {"episodes": n, "success_rate": p,
                             "success_rate_se": float(np.sqrt(p * (1 - p) / n))}
    for name, values in (("spl", [e.spl for e in episodes]),
                         ("collisions_per_episode", [e.collision_steps for e in episodes]),
                         ("traffic_collisions_per_episode",
                          [e.traffic_collision_steps for e in episodes]),
                         ("collision_episodes", [e.collision_steps > 0 for e in episodes]),
                         ("tipped_over_episodes", [e.tipped_over for e in episodes]),
                         ("time_to_goal", [e.time for e in ok]),
                         ("path_ratio", [e.path_ratio for e in ok]),
                         ("misled_steps_per_episode", misled),
                         ("misled_episodes", [m > 0 for m in misled])):
        out[name], out[f"{name}_se"] = mean_and_se(values)
    out["belief_rmse"], out["belief_rmse_se"] = _rmse_and_se([e.belief_rmse for e in episodes])
    return out


def _rmse_and_se(episode_rmse: Sequence[float]) -> tuple[float, float]:
    """RMSE over the episodes (each weighted alike) from their RMSEs, with its delta-method
    standard error ``se(mean e^2) / (2 RMSE)``."""
    squares = np.asarray(episode_rmse, dtype=np.float64) ** 2
    msq, se = mean_and_se(squares[np.isfinite(squares)])
    rmse = float(np.sqrt(msq))
    return rmse, (se / (2 * rmse) if rmse > 0 else 0.0)


def as_records(episodes: Sequence[Episode]) -> list[dict[str, Any]]:
    """Episodes as JSON-ready dicts (with the path ratio)."""
    return [{**asdict(e), "path_ratio": e.path_ratio} for e in episodes]


#: the table columns of :func:`metric_cells`: (summary key, header, decimals)
METRIC_COLUMNS = (("success_rate", "success", 2), ("spl", "SPL", 2),
                  ("collisions_per_episode", "collisions / episode", 2),
                  ("time_to_goal", "time to goal (s)", 1), ("belief_rmse", "belief RMSE (m)", 2),
                  ("misled_steps_per_episode", "misled steps / episode", 2))


def metric_cells(summary: dict[str, float]) -> list[str]:
    """Markdown cells "value ± se" of a :func:`summarize` result, in :data:`METRIC_COLUMNS`
    order ("n/a" where undefined: no time to goal without a success, no misled steps for a
    source without a status or a summary written before they were measured)."""
    cells = []
    for key, _, d in METRIC_COLUMNS:
        value = summary.get(key, float("nan"))
        cells.append("n/a" if np.isnan(value) else f"{value:.{d}f} ± {summary[key + '_se']:.{d}f}")
    return cells
