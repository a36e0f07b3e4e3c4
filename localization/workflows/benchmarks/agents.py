"""Benchmark: PPO on the GSE belief against PPO on the true pose, on held-out cities, starting
anywhere on the street surface (issue 17; ``appearance-nav bench --only agents``, options
``--agents-<option>``).

    appearance-nav bench --only agents
    appearance-nav bench --only agents --agents-active-penalty 0.01   # + active localization

1. Localizers: one per city (the training city and every held-out city) fitted on
   ``n_train`` images over the whole street surface at every heading
   (:func:`~localization.workflows.tracking.fit_city_localizer` with ``lanes="free"``,
   PixelPCA(``n_components``)), read from ``<localizers>/city_<k>.npz`` or fitted and written
   there when missing.
2. Training (:func:`~localization.workflows.training.train_agent`, same budget and seed for
   every policy) on ``train_city`` with random starts (any free pose, any heading): PPO on
   the true pose ("oracle"), and PPO on the belief ("belief": the detecting EKF, the belief's
   status in the observation, a kidnap at each of ``train_kidnap_at``); with
   ``active_penalty > 0`` also "active": the belief policy with the belief-entropy reward
   term (:class:`agents.rewards.StreetProgressReward`). A policy whose ``train.json`` exists
   under ``<out>/agents/<name>/`` is reused (its recorded training time is reported).
3. Evaluation on the held-out cities ``eval_cities`` (never used to choose anything), random
   starts, ``episodes`` per city with reset seeds ``first_seed ..`` (the same for every
   row): PPO on the true pose, PPO on the belief. With "active": plain and active policy on
   the belief (the same budget: with ``active_timesteps`` < ``total_timesteps`` both runs'
   checkpoints at that step), ``active_episodes`` per city, once with a kidnap at step ``kidnap_step`` of
   every episode and once at night (``conditions="night"``): success, path length, belief
   RMSE.

Writes ``<out>/bench_agents.json`` and ``<out>/bench_agents.md``. Targets (PASS/MISS): PPO on the
belief reaches >= 0.97x the success rate of PPO on the true pose over >= 200 held-out
episodes; each training run <= 30 min.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym

from localization.workflows.benchmarks.agents_eval import (
    EpisodeTask,
    localizer_path,
    run_episode_task,
    summarize_row,
)
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.parallel import map_tasks
from localization.workflows.tracking import fit_city_localizer
from localization.workflows.training import TrainConfig, train_agent

__all__ = ["TARGET_EPISODES", "TARGET_RATIO", "TARGET_TRAIN_MINUTES", "AgentsBenchConfig",
           "run_agents_bench"]

TARGET_RATIO = 0.97
TARGET_EPISODES = 200
TARGET_TRAIN_MINUTES = 30.0
TASK_SEEDS = 10  # episodes per evaluation task


@dataclass
class AgentsBenchConfig:
    """Settings of the agents benchmark."""

    train_city: int = field(default=0, metadata={"help": "the city the policies train on"})
    eval_cities: str = field(default="21,22", metadata={
        "help": "comma-separated held-out cities of the evaluation (never used to tune)"})
    localizers: str = field(default="results/localizers_free", metadata={
        "help": "folder of the cities' street-surface localizers city_<k>.npz (fitted if "
                "missing)"})
    n_train: int = field(default=40000, metadata={
        "help": "street-surface images per localizer fitted here"})
    n_components: int = field(default=64, metadata={"help": "PixelPCA components"})
    n_drive: int = field(default=1500, metadata={
        "help": "steps of each noise-calibration drive of a localizer fitted here"})
    total_timesteps: int = field(default=400_000, metadata={"help": "PPO steps per policy"})
    eval_freq: int = field(default=50_000, metadata={
        "help": "steps between the EvalCallback's evaluations (counted in the training time)"})
    n_envs: int = field(default=8, metadata={"help": "environments per rollout"})
    vec_env: str = field(default="subproc", metadata={
        "help": "'subproc' (forked env workers) or 'dummy' (one process)"})
    seed: int = field(default=0, metadata={"help": "training seed (the same for every policy)"})
    status: bool = field(default=True, metadata={
        "help": "the belief policies see the belief status"})
    bumper: bool = field(default=True, metadata={
        "help": "every policy feels the bump sensor (agents.observations)"})
    train_kidnap_at: str = field(default="100", metadata={
        "help": "comma-separated steps of each belief training episode with a kidnap"})
    detect_divergence: bool = field(default=True, metadata={
        "help": "the belief's EKF notices when it is lost (training and evaluation)"})
    episodes: int = field(default=100, metadata={"help": "evaluation episodes per city"})
    first_seed: int = field(default=3_000_000, metadata={"help": "first evaluation reset seed"})
    active_penalty: float = field(default=0.0, metadata={
        "help": "> 0: also train with this belief-entropy reward weight and compare it with "
                "the plain reward under kidnapping and at night"})
    active_timesteps: int = field(default=0, metadata={
        "help": "PPO steps of the active policy (0: total_timesteps); when fewer, the plain "
                "comparison is the belief policy's checkpoint at that step (a multiple of "
                "100000, the checkpoint interval)"})
    active_episodes: int = field(default=50, metadata={
        "help": "episodes per city and condition of the active-localization comparison"})
    kidnap_step: int = field(default=50, metadata={
        "help": "the comparison's kidnap step of every episode"})
    workers: int = field(default=2, metadata={"help": "evaluation worker processes"})
    motion_noise: float = field(default=0.1, metadata={"help": "actuation noise of the env"})
    out: str = field(default="results", metadata={"help": "where bench_agents.* and agents/ go"})

    def cities(self) -> list[int]:
        """The held-out cities as ints."""
        return [int(c) for c in self.eval_cities.split(",") if c.strip()]


def ensure_localizers(args: AgentsBenchConfig) -> dict[int, float]:
    """Fit and write the missing localizers; seconds per fitted city."""
    seconds = {}
    for city in dict.fromkeys([args.train_city, *args.cities()]):
        path = localizer_path(args.localizers, city)
        if path.is_file():
            continue
        t0 = time.perf_counter()
        env = gym.make("AppearanceNav-v0", scene_seed=city, motion_noise=args.motion_noise,
                       max_episode_steps=None)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            loc, _ = fit_city_localizer(
                env, n_train=args.n_train, lanes="free", n_drive=args.n_drive, seed=args.seed,
                localizer_params={"features_params": {"n_components": args.n_components}})
        env.close()
        path.parent.mkdir(parents=True, exist_ok=True)
        loc.save(path)
        seconds[city] = round(time.perf_counter() - t0, 1)
    return seconds


def _train_configs(args: AgentsBenchConfig) -> dict[str, TrainConfig]:
    out = Path(args.out) / "agents"
    common = {"scene_seed": args.train_city, "motion_noise": args.motion_noise,
              "start": "random", "total_timesteps": args.total_timesteps,
              "n_envs": args.n_envs, "vec_env": args.vec_env, "seed": args.seed,
              "eval_freq": args.eval_freq, "progress": False, "bumper": args.bumper,
              "localizer": str(localizer_path(args.localizers, args.train_city))}
    belief = {**common, "pose_source": "belief", "status": args.status,
              "kidnap_at": args.train_kidnap_at, "detect_divergence": args.detect_divergence}
    configs = {"oracle": TrainConfig(pose_source="oracle", out=str(out / "oracle"), **common),
               "belief": TrainConfig(out=str(out / "belief"), **belief)}
    if args.active_penalty > 0:
        steps = args.active_timesteps or args.total_timesteps
        configs["active"] = TrainConfig(out=str(out / "active"),
                                        uncertainty_penalty=args.active_penalty,
                                        **{**belief, "total_timesteps": steps})
    return configs


def comparison_policies(args: AgentsBenchConfig, policies: dict[str, str]) -> dict[str, str]:
    """The plain ("belief") and active policies of the comparison: the final ones, or, when
    ``active_timesteps`` < ``total_timesteps``, both runs' checkpoints at ``active_timesteps``
    (the same number of updates)."""
    steps = args.active_timesteps or args.total_timesteps
    if steps == args.total_timesteps:
        return policies
    chosen = {}
    for name in ("belief", "active"):
        checkpoint = Path(policies[name]).parent / "checkpoints" / f"policy_{steps}.pt"
        if not checkpoint.is_file():
            raise FileNotFoundError(f"no checkpoint {checkpoint} for active_timesteps={steps} "
                                    "(checkpoints are every 100000 steps)")
        chosen[name] = str(checkpoint)
    return {**policies, **chosen}


def train_policies(args: AgentsBenchConfig) -> dict[str, dict[str, Any]]:
    """Train (or reuse) every policy; its train.json summary by name."""
    summaries = {}
    for name, config in _train_configs(args).items():
        record = Path(config.out) / config.pose_source / "train.json"
        summaries[name] = json.loads(record.read_text()) if record.is_file() \
            else train_agent(config)
        summaries[name]["policy"] = str(Path(config.out) / config.pose_source / "policy.pt")
    return summaries


def _rows(args: AgentsBenchConfig, policies: dict[str, str],
          ) -> list[tuple[str, str, dict[str, Any], int]]:
    """(row name, source, EpisodeTask settings, episodes per city) of every evaluation row."""
    rows = [("PPO, true pose", "oracle", {"agent": policies["oracle"]}, args.episodes),
            ("PPO, belief", "belief", {"agent": policies["belief"]}, args.episodes)]
    if "active" in policies:
        policies = comparison_policies(args, policies)
        for condition, settings in (("kidnap", {"kidnap_at": (args.kidnap_step,)}),
                                    ("night", {"conditions": "night"})):
            for name in ("belief", "active"):
                label = "plain" if name == "belief" else f"active ({args.active_penalty:g})"
                rows.append((f"{label}, {condition}", "belief",
                             {"agent": policies[name], **settings}, args.active_episodes))
    return rows


def evaluate(args: AgentsBenchConfig, policies: dict[str, str],
             only: Collection[str] | None = None) -> list[dict[str, Any]]:
    """Every row (or the rows named in ``only``) on every held-out city (pooled and per
    city)."""
    tasks, owners = [], []
    for name, source, settings, n in _rows(args, policies):
        if only is not None and name not in only:
            continue
        for city in args.cities():
            seeds = list(range(args.first_seed, args.first_seed + n))
            for i in range(0, n, TASK_SEEDS):
                tasks.append(EpisodeTask(source=source, city=city, localizers=args.localizers,
                                         seeds=tuple(seeds[i:i + TASK_SEEDS]),
                                         detect_divergence=args.detect_divergence,
                                         motion_noise=args.motion_noise, **settings))
                owners.append((name, city))
    results = map_tasks(run_episode_task, tasks, workers=args.workers, desc="episodes")
    runs: dict[tuple[str, int], tuple[list, float]] = {}
    for owner, (episodes, seconds) in zip(owners, results):
        done, total = runs.get(owner, ([], 0.0))
        runs[owner] = (done + episodes, total + seconds)
    rows = []
    for name in dict.fromkeys(n for n, _ in owners):
        pooled = [runs[name, c] for c in args.cities()]
        rows.append(summarize_row(name, [e for eps, _ in pooled for e in eps],
                                  sum(s for _, s in pooled)))
        rows[-1]["per_city"] = {c: summarize_row(name, *runs[name, c])["success_rate"]
                                for c in args.cities()}
    return rows


def _targets(rows: list[dict[str, Any]], training: dict[str, dict[str, Any]],
             ) -> list[tuple[str, Any, str, bool]]:
    by = {r["row"]: r for r in rows}
    oracle, belief = by["PPO, true pose"], by["PPO, belief"]
    ratio = belief["success_rate"] / max(oracle["success_rate"], 1e-9)
    return [
        ("PPO success, belief / true pose", round(ratio, 3), f">= {TARGET_RATIO}",
         ratio >= TARGET_RATIO),
        ("held-out episodes per row", belief["episodes"], f">= {TARGET_EPISODES}",
         belief["episodes"] >= TARGET_EPISODES),
        *((f"PPO training time, {name} (min)", round(s["train_seconds"] / 60, 1),
           f"<= {TARGET_TRAIN_MINUTES:.0f}", s["train_seconds"] / 60 <= TARGET_TRAIN_MINUTES)
          for name, s in training.items()),
    ]


def _markdown(args: AgentsBenchConfig, rows: list[dict[str, Any]],
              targets: list[tuple[str, Any, str, bool]]) -> str:
    head = ("| row | episodes | success rate | per city | path ratio | path length (m) "
            "| collision episodes | belief RMSE (m) |\n|---|---:|---:|---|---:|---:|---:|---:|")
    lines = [f"| {r['row']} | {r['episodes']} | {r['success_rate']:.3f} | "
             + ", ".join(f"{c}: {v:.2f}" for c, v in r["per_city"].items())
             + f" | {r['path_ratio']:.2f} | {r['path_length']:.1f} "
               f"| {r['collision_episodes']:.2f} | {r['belief_rmse']:.2f} |" for r in rows]
    target_lines = [f"| {t} | {v} | {lim} | {'PASS' if ok else 'MISS'} |"
                    for t, v, lim, ok in targets]
    return (f"# PPO on the belief, held-out cities {args.eval_cities}\n\nTrained on city "
            f"{args.train_city} ({args.total_timesteps} steps per policy, seed {args.seed}), "
            f"random starts, reset seeds {args.first_seed}..\n\n" + head + "\n"
            + "\n".join(lines) + "\n\n| target | value | limit | status |\n|---|---:|---|---|\n"
            + "\n".join(target_lines) + "\n")


def run_agents_bench(args: AgentsBenchConfig) -> dict[str, Any]:
    """Fit the missing localizers, train (or reuse) the policies, evaluate, write
    ``bench_agents.json`` / ``.md``; return the result."""
    fitted = ensure_localizers(args)
    training = train_policies(args)
    t0 = time.perf_counter()
    rows = evaluate(args, {name: s["policy"] for name, s in training.items()})
    targets = _targets(rows, training)
    result = {"args": dataclasses.asdict(args), **provenance(),
              "localizer_fit_seconds": fitted, "training": training, "evaluation": rows,
              "evaluation_seconds": round(time.perf_counter() - t0, 1),
              "targets": [{"target": t, "value": v, "limit": lim, "pass": ok}
                          for t, v, lim, ok in targets]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    md = _markdown(args, rows, targets)
    (out / "bench_agents.md").write_text(md)
    (out / "bench_agents.json").write_text(json.dumps(result, indent=2, default=str))
    print(md)
    return result
