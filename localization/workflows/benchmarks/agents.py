"""Benchmark: PPO on the GSE belief against PPO on the true pose, same training budget
(``appearance-nav bench --only agents``; its options are ``--agents-<option>``).

    appearance-nav bench --only agents       # needs results/localizer.npz (make demo)
    appearance-nav bench --only agents --agents-total-timesteps 50000 --agents-episodes 20

1. :func:`~localization.workflows.training.train_agent` trains PPO on the oracle (true pose)
   and on the belief with the same number of environment steps (and seeds), each in this
   process, one after the other;
2. :func:`~localization.workflows.navigation.evaluate_agents` evaluates the scripted agent on
   all three pose sources (oracle, belief, dead reckoning) and each PPO policy on the source it
   was trained on, over the same ``episodes`` held-out resets.

Writes ``<out>/bench_agents.json`` and ``<out>/bench_agents.md``. Targets (PASS/MISS): PPO on the
belief reaches >= 0.9x the success rate of PPO on the true pose; each training run <= 30 min.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from localization.workflows.navigation import EvalConfig, evaluate_agents
from localization.workflows.training import TrainConfig, train_agent

__all__ = ["TARGET_RATIO", "TARGET_TRAIN_MINUTES", "AgentsBenchConfig", "run_agents_bench"]

TARGET_RATIO = 0.9
TARGET_TRAIN_MINUTES = 30.0


@dataclass
class AgentsBenchConfig:
    """Settings of the agents benchmark."""

    localizer: str = field(default="results/localizer.npz", metadata={
        "help": "fitted AppearanceLocalizer of the city (make demo writes it)"})
    total_timesteps: int = field(default=400_000, metadata={"help": "PPO steps per pose source"})
    eval_freq: int = field(default=50_000, metadata={
        "help": "steps between the EvalCallback's evaluations (counted in the training time)"})
    n_envs: int = field(default=8, metadata={"help": "environments per rollout"})
    vec_env: str = field(default="subproc", metadata={
        "help": "'subproc' (forked env workers) or 'dummy' (one process), for both sources"})
    seed: int = field(default=0, metadata={"help": "training seed (the same for both sources)"})
    episodes: int = field(default=100, metadata={
        "help": "evaluation episodes per agent and source"})
    scene_seed: int = field(default=0, metadata={"help": "the city"})
    motion_noise: float = field(default=0.1, metadata={"help": "actuation noise of the env"})
    out: str = field(default="results", metadata={"help": "where bench_agents.* and agents/ go"})


def run_agents_bench(args: AgentsBenchConfig) -> dict:
    """Train on both sources, evaluate, write ``bench_agents.json`` / ``.md``; return the
    result."""
    out = Path(args.out)
    common = {"localizer": args.localizer, "scene_seed": args.scene_seed,
              "motion_noise": args.motion_noise}
    training = {}
    for source in ("oracle", "belief"):
        training[source] = train_agent(TrainConfig(
            pose_source=source, total_timesteps=args.total_timesteps, n_envs=args.n_envs,
            vec_env=args.vec_env, seed=args.seed, eval_freq=args.eval_freq,
            out=str(out / "agents"), **common))
    t0 = time.perf_counter()
    rows = evaluate_agents(EvalConfig(episodes=args.episodes, policies=str(out / "agents"),
                                      out=str(out), **common))
    success = {(r["agent"], r["source"]): r["success_rate"] for r in rows}
    ratio = success[("ppo", "belief")] / max(success[("ppo", "oracle")], 1e-9)
    minutes = {s: training[s]["train_seconds"] / 60 for s in training}
    targets = [
        ("PPO success, belief / oracle", round(ratio, 3), f">= {TARGET_RATIO}",
         ratio >= TARGET_RATIO),
        *((f"PPO training time on {s} (min)", round(m, 1), f"<= {TARGET_TRAIN_MINUTES:.0f}",
           m <= TARGET_TRAIN_MINUTES) for s, m in minutes.items()),
    ]
    result = {"args": dataclasses.asdict(args), "machine": platform.platform(),
              "training": training, "evaluation": rows,
              "evaluation_seconds": round(time.perf_counter() - t0, 1),
              "targets": [{"target": t, "value": v, "limit": lim, "pass": ok}
                          for t, v, lim, ok in targets]}
    md = (out / "agents.md").read_text() + (
        f"\nPPO: {args.total_timesteps} steps per pose source (seed {args.seed}).\n\n"
        "| target | value | limit | status |\n|---|---:|---|---|\n"
        + "\n".join(f"| {t} | {v} | {lim} | {'PASS' if ok else 'MISS'} |"
                    for t, v, lim, ok in targets) + "\n")
    (out / "bench_agents.md").write_text(md)
    (out / "bench_agents.json").write_text(json.dumps(result, indent=2))
    print(md)
    return result
