"""Evaluate the navigators on each pose source: success, path ratio, collisions, time to goal.

    appearance-nav eval --episodes 100
    appearance-nav eval --agents scripted --sources oracle,dead_reckoning
    appearance-nav eval --agents scripted --episodes 5 --rerun results/eval.rrd
    appearance-nav eval --episodes 400 --workers 2           # 2 local worker processes
    appearance-nav eval --episodes 4000 --workers 64 --ray-address auto   # a Ray cluster

For every agent (the scripted street navigator; PPO policies trained by
``appearance-nav train``, each evaluated on the pose source it was trained on; a missing
policy is skipped with a note) and pose source (oracle = true pose, belief = the GSE/EKF
belief from images, dead_reckoning = the motion model alone), the same ``episodes`` resets
(seeds ``seed .. seed + episodes - 1``) are run. Writes ``<out>/agents.md`` (table) and
``<out>/agents.json`` (summary and every episode). ``--rerun FILE.rrd`` (the ``viewer`` extra)
also records the first ``--rerun-episodes`` episodes of each agent and source, step by step,
for the Rerun viewer (``rerun FILE.rrd``; in this process only: ``--workers 1``).

``--workers N`` splits the episodes by seed over N local processes, ``--ray-address`` runs
them as Ray tasks (the ``distributed`` extra); each worker builds its own env and agent, so
every episode's record is the serial run's.
"""

from __future__ import annotations

import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from agents.sources import POSE_SOURCES, STARTS
from localization.cli._args import (
    UsageError,
    check_choice,
    check_choices,
    check_env,
    check_existing_file,
    check_numbers,
    check_output_dir,
)
from localization.cli._parallel import check_parallel
from localization.cli._rerun import check_rerun
from localization.localizer import MEASUREMENTS
from localization.workflows.navigation import AGENTS, EvalConfig, evaluate_agents

__all__ = ["Args", "check", "run"]

Args = EvalConfig


def check(args: Args) -> None:
    """Every option is valid (raises :class:`~localization.cli._args.UsageError`)."""
    check_choices("agents", args.agents, AGENTS)
    sources = check_choices("sources", args.sources, POSE_SOURCES)
    if set(sources) - {"oracle"}:
        check_existing_file("localizer", args.localizer)
    if args.measurement:
        check_choice("measurement", args.measurement, MEASUREMENTS)
    check_env(args)
    check_choice("start", args.start, STARTS)
    check_numbers(args, positive=("episodes",),
                  non_negative=("seed", "rerun_episodes", "max_episode_steps"))
    check_output_dir("out", args.out)
    check_rerun(args.rerun)
    check_parallel(args)
    if args.rerun and (args.workers != 1 or args.ray_address):
        raise UsageError("rerun", "records the episodes in this process: use it with "
                                  "--workers 1 and no --ray-address")


def run(args: Args) -> None:
    """Evaluate (:func:`localization.workflows.navigation.evaluate_agents`)."""
    evaluate_agents(args)
