"""Evaluate navigators on pose sources: success, path ratio, collisions, time to goal
(``appearance-nav eval``).

For every agent (the scripted street navigator; PPO policies trained by
``appearance-nav train``, each evaluated on the pose source it was trained on) and pose
source (oracle = true pose, belief = the GSE/EKF belief from images, dead_reckoning = the
motion model alone), the same ``episodes`` resets (start pose and goal, seeds
``seed .. seed + episodes - 1``, disjoint from the training and evaluation resets of
``appearance-nav train``) are run. Writes ``<out>/agents.md`` (table) and
``<out>/agents.json`` (summary and every episode).

Columns: success rate (goal reached before truncation), path ratio (distance driven / shortest
street path, over successes), collision episodes (share of episodes with any contact), time
to goal (simulated seconds, over successes), belief RMSE (m, belief mean vs true position).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from agents.evaluation import as_records, run_episodes, summarize
from agents.ppo import PPOAgent
from agents.scripted import ScriptedAgent
from agents.sources import POSE_SOURCES, make_pose_env
from localization.localizer import AppearanceLocalizer
from localization.workflows.agent_env import AgentEnvSettings, city_options
from localization.workflows.rerun_log import RerunLog, RerunRecorder

__all__ = ["AGENTS", "EvalConfig", "agents_table", "evaluate_agents"]

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


def agents_table(rows: list[dict]) -> str:
    """The markdown table of the summaries."""
    header = ("| agent | pose source | episodes | success rate | path ratio | collision episodes "
              "| time to goal (s) | belief RMSE (m) |")
    lines = [header, "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['agent']} | {r['source']} | {r['episodes']} | {r['success_rate']:.2f} "
                     f"| {r['path_ratio']:.2f} | {r['collision_episodes']:.2f} "
                     f"| {r['time_to_goal']:.1f} | {r['belief_rmse']:.2f} |")
    return "\n".join(lines)


def evaluate_agents(args: EvalConfig) -> list[dict]:
    """Run every agent on every pose source; write ``agents.md`` / ``agents.json`` to
    ``args.out``; return one summary row per (agent, source)."""
    sources = args.sources.split(",")
    localizer = None
    if set(sources) - {"oracle"}:
        localizer = AppearanceLocalizer.load(args.localizer)
    seeds = range(args.seed, args.seed + args.episodes)
    rows, episodes = [], {}
    log = RerunLog(args.rerun) if args.rerun else None
    for source in sources:
        env = make_pose_env(source, localizer, measurement=args.measurement or None,
                            scene_seed=args.scene_seed, camera=args.camera,
                            image_size=(args.image_size, args.image_size),
                            motion_noise=args.motion_noise,
                            max_episode_steps=args.max_episode_steps, start=args.start,
                            **city_options(source, args.allow_other_city))
        city = env.unwrapped.city
        for name in args.agents.split(","):
            if name == "scripted":
                agent = ScriptedAgent(city)
            else:
                policy = Path(args.policies) / source / "policy.pt"
                if not policy.exists():
                    print(f"skipping ppo on {source}: no {policy} (run appearance-nav train)")
                    continue
                agent = PPOAgent.load(policy, city)
            t0 = time.perf_counter()
            runs = run_episodes(env if log is None else RerunRecorder(
                env, log, f"{name}/{source}", args.rerun_episodes,
                path=lambda agent=agent: getattr(agent, "path", None)),
                agent, seeds, desc=f"{name} on {source}")
            summary = {"agent": name, "source": source, **summarize(runs),
                       "wall_seconds": round(time.perf_counter() - t0, 1)}
            rows.append(summary)
            episodes[f"{name}/{source}"] = as_records(runs)
            print(agents_table([summary]).splitlines()[-1], flush=True)
        env.close()
    if log is not None:
        log.close()
        print(f"Rerun recording: {args.rerun} (open it with: rerun {args.rerun})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    md = (f"# Navigation on the pose belief\n\nCity {args.scene_seed}, {args.camera} "
          f"{args.image_size}x{args.image_size}, motion noise {args.motion_noise}, "
          f"{args.episodes} episodes (reset seeds {args.seed}..), truncation at "
          f"{args.max_episode_steps} steps.\n\n{agents_table(rows)}\n")
    (out / "agents.md").write_text(md)
    (out / "agents.json").write_text(json.dumps({"args": dataclasses.asdict(args), "rows": rows,
                                                  "episodes": episodes}, indent=1))
    print(md)
    return rows
