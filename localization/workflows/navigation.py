"""Evaluate navigators on pose sources: success, path ratio, collisions, time to goal
(``appearance-nav eval``).

For every agent (the scripted street navigator; PPO policies trained by
``appearance-nav train``, each evaluated on the pose source it was trained on) and pose
source (oracle = true pose, belief = the GSE/EKF belief from images, dead_reckoning = the
motion model alone), the same ``episodes`` resets (start pose and goal, seeds
``seed .. seed + episodes - 1``, disjoint from the training and evaluation resets of
``appearance-nav train``) are run. Writes ``<out>/agents.md`` (table) and
``<out>/agents.json`` (summary and every episode).

Columns, each with its standard error (:func:`agents.evaluation.summarize`): success (goal
reached before truncation), SPL (success weighted by path length, Anderson et al. 2018, the
shortest street path as the reference), collisions per episode (steps in contact), time to goal
(simulated seconds, over successes), belief RMSE (m, belief mean vs true position).

With ``workers > 1`` or a ``ray_address`` the episodes of each agent and source are split by
seed into tasks (:func:`~localization.workflows.parallel.map_tasks`); each worker builds its
own env and agent, and an episode depends only on its reset seed, so every record equals the
serial run's (only ``wall_seconds`` differs: the summed seconds of the row's tasks).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from agents.evaluation import (
    METRIC_COLUMNS,
    Episode,
    as_records,
    metric_cells,
    run_episodes,
    summarize,
)
from agents.ppo import PPOAgent
from agents.scripted import ScriptedAgent
from agents.sources import POSE_SOURCES, agent_episode_steps, make_pose_env
from localization.loading import load_localizer
from localization.localizer import AppearanceLocalizer
from localization.workflows.agent_env import AgentEnvSettings, city_options
from localization.workflows.parallel import RAY_ADDRESS_HELP, WORKERS_HELP, map_tasks, worker_env
from localization.workflows.rerun_log import RerunLog, RerunRecorder

__all__ = ["AGENTS", "EvalConfig", "EvalTask", "agents_table", "evaluate_agents",
           "run_eval_task"]

#: the navigators :func:`evaluate_agents` knows
AGENTS = ("scripted", "ppo")


@dataclass
class EvalConfig(AgentEnvSettings):
    """Settings of the evaluation (the options of ``appearance-nav eval``)."""

    agents: str = field(default="scripted,ppo", metadata={
        "help": "comma-separated: scripted, ppo"})
    sources: str = field(default=",".join(POSE_SOURCES), metadata={
        "help": "comma-separated pose sources: " + ", ".join(POSE_SOURCES)})
    policies: str = field(default="results/agents", metadata={
        "help": "folder with <source>/policy.pt from appearance-nav train"})
    episodes: int = field(default=100, metadata={"help": "episodes per agent and source"})
    seed: int = field(default=2_000_000, metadata={"help": "first reset seed"})
    out: str = field(default="results", metadata={"help": "where agents.md / agents.json go"})
    rerun: str = field(default="", metadata={
        "help": "also record episodes to this Rerun .rrd file (the viewer extra); empty: none"})
    rerun_episodes: int = field(default=1, metadata={
        "help": "with --rerun: the first this many episodes of each agent and source"})
    workers: int = field(default=1, metadata={"help": WORKERS_HELP})
    ray_address: str = field(default="", metadata={"help": RAY_ADDRESS_HELP})


def agents_table(rows: list[dict]) -> str:
    """The markdown table of the summaries (each metric ± its standard error)."""
    headers = [h for _, h, _ in METRIC_COLUMNS]
    lines = ["| agent | pose source | episodes | " + " | ".join(headers) + " |",
             "|---|---|---:|" + "---:|" * len(headers)]
    for r in rows:
        lines.append(f"| {r['agent']} | {r['source']} | {r['episodes']} | "
                     + " | ".join(metric_cells(r)) + " |")
    return "\n".join(lines)


def _make_env(args: EvalConfig, source: str, localizer: AppearanceLocalizer | None) -> Any:
    """The pose env of ``source`` (the settings of ``args``)."""
    return make_pose_env(source, localizer, measurement=args.measurement or None,
                         scene_seed=args.scene_seed, city_size=args.city_size,
                         camera=args.camera, image_size=(args.image_size, args.image_size),
                         motion_noise=args.motion_noise,
                         max_episode_steps=args.max_episode_steps or None, start=args.start,
                         **city_options(source, args.allow_other_city))


def _policy(args: EvalConfig, source: str) -> Path:
    return Path(args.policies) / source / "policy.pt"


def _make_agent(args: EvalConfig, name: str, source: str, city: Any) -> Any:
    """The navigator ``name`` for ``source`` (PPO: its policy must exist)."""
    return ScriptedAgent(city) if name == "scripted" else PPOAgent.load(_policy(args, source),
                                                                        city)


def _runs(args: EvalConfig, sources: list[str]) -> list[tuple[str, str]]:
    """The (agent, source) pairs to run, in table order (PPO without a policy: a note)."""
    pairs = []
    for source in sources:
        for name in args.agents.split(","):
            if name == "ppo" and not _policy(args, source).exists():
                print(f"skipping ppo on {source}: no {_policy(args, source)} "
                      "(run appearance-nav train)")
                continue
            pairs.append((name, source))
    return pairs


@dataclass(frozen=True)
class EvalTask:
    """The episodes of one agent on one pose source with the given reset seeds."""

    config: EvalConfig
    agent: str
    source: str
    seeds: tuple[int, ...]


_LOCALIZERS: dict[str, AppearanceLocalizer] = {}


def _localizer(path: str) -> AppearanceLocalizer:
    """This process's copy of the localizer file (loaded once)."""
    if path not in _LOCALIZERS:
        _LOCALIZERS[path] = load_localizer(path)
    return _LOCALIZERS[path]


def run_eval_task(task: EvalTask) -> tuple[list[Episode], float]:
    """Run ``task``'s episodes (:func:`~localization.workflows.parallel.worker_env`: the env
    kept while the next task shares it); episodes and seconds taken."""
    args, t0 = task.config, time.perf_counter()
    key = (dataclasses.astuple(dataclasses.replace(args, workers=1, ray_address="")),
           task.source)
    env = worker_env(key, lambda: _make_env(
        args, task.source, None if task.source == "oracle" else _localizer(args.localizer)))
    agent = _make_agent(args, task.agent, task.source, env.unwrapped.city)
    runs = run_episodes(env, agent, task.seeds, progress=False)
    return runs, time.perf_counter() - t0


def _evaluate_parallel(args: EvalConfig, pairs: list[tuple[str, str]],
                       ) -> dict[tuple[str, str], tuple[list[Episode], float]]:
    """Every pair's episodes, split by seed into tasks over the workers."""
    seeds = list(range(args.seed, args.seed + args.episodes))
    size = max(1, math.ceil(len(seeds) * len(pairs) / (4 * args.workers)))  # ~4 tasks a worker
    tasks = [EvalTask(args, name, source, tuple(seeds[i:i + size]))
             for name, source in pairs for i in range(0, len(seeds), size)]
    results = map_tasks(run_eval_task, tasks, workers=args.workers,
                        ray_address=args.ray_address, desc=f"episodes ({len(tasks)} tasks)")
    runs: dict[tuple[str, str], tuple[list[Episode], float]] = {p: ([], 0.0) for p in pairs}
    for task, (episodes, seconds) in zip(tasks, results):
        done, total = runs[task.agent, task.source]
        runs[task.agent, task.source] = (done + episodes, total + seconds)
    return runs


def _evaluate_serial(args: EvalConfig, pairs: list[tuple[str, str]],
                     ) -> dict[tuple[str, str], tuple[list[Episode], float]]:
    """Every pair's episodes in this process (one env per source; optional Rerun log)."""
    localizer = None
    if {source for _, source in pairs} - {"oracle"}:
        localizer = load_localizer(args.localizer)
    seeds = range(args.seed, args.seed + args.episodes)
    log = RerunLog(args.rerun) if args.rerun else None
    runs = {}
    for source in dict.fromkeys(source for _, source in pairs):
        env = _make_env(args, source, localizer)
        for name in [n for n, s in pairs if s == source]:
            agent = _make_agent(args, name, source, env.unwrapped.city)
            t0 = time.perf_counter()
            episodes = run_episodes(env if log is None else RerunRecorder(
                env, log, f"{name}/{source}", args.rerun_episodes,
                path=lambda agent=agent: getattr(agent, "path", None)),
                agent, seeds, desc=f"{name} on {source}")
            runs[name, source] = (episodes, time.perf_counter() - t0)
            print(agents_table([_summary(name, source, *runs[name, source])]).splitlines()[-1],
                  flush=True)
        env.close()
    if log is not None:
        log.close()
        print(f"Rerun recording: {args.rerun} (open it with: rerun {args.rerun})")
    return runs


def _summary(name: str, source: str, episodes: list[Episode], seconds: float) -> dict:
    return {"agent": name, "source": source, **summarize(episodes),
            "wall_seconds": round(seconds, 1)}


def evaluate_agents(args: EvalConfig) -> list[dict]:
    """Run every agent on every pose source; write ``agents.md`` / ``agents.json`` to
    ``args.out``; return one summary row per (agent, source).

    Raises
    ------
    ValueError
        If ``args.rerun`` is asked with ``workers > 1`` or a Ray address (a recording is
        written by this process).
    """
    parallel = args.workers != 1 or bool(args.ray_address)
    if parallel and args.rerun:
        raise ValueError("rerun records the episodes in this process: use workers=1 and no "
                         "ray_address with it")
    pairs = _runs(args, args.sources.split(","))
    runs = (_evaluate_parallel if parallel else _evaluate_serial)(args, pairs)
    rows = [_summary(name, source, *runs[name, source]) for name, source in pairs]
    episodes = {f"{name}/{source}": as_records(runs[name, source][0]) for name, source in pairs}
    if parallel:
        print("\n".join(agents_table(rows).splitlines()[2:]), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    limit = args.max_episode_steps or agent_episode_steps(args.city_size)
    md = (f"# Navigation on the pose belief\n\nCity {args.scene_seed} ({args.city_size:g} m), "
          f"{args.camera} {args.image_size}x{args.image_size}, motion noise "
          f"{args.motion_noise}, {args.episodes} episodes (reset seeds {args.seed}..), "
          f"truncation at {limit} steps.\n\n{agents_table(rows)}\n")
    (out / "agents.md").write_text(md)
    settings = {k: v for k, v in dataclasses.asdict(args).items()
                if k not in ("workers", "ray_address")}
    (out / "agents.json").write_text(json.dumps({"args": settings, "rows": rows,
                                                  "episodes": episodes}, indent=1))
    print(md)
    return rows
