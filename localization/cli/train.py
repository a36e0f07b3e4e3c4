"""Train a PPO navigator (stable-baselines3 ``MultiInputPolicy``) on a pose source.

    appearance-nav train --pose-source belief --localizer results/localizer.npz
    appearance-nav train --pose-source oracle --total-timesteps 300000

The policy sees the street plan and goal in the belief's body frame plus the belief's standard
deviations, never the true pose; it is rewarded for progress along the street path. Writes to
``<out>/<pose_source>/``: ``policy.pt`` + ``policy.json`` (loadable without pickle by
``agents.ppo.PPOAgent.load``), ``checkpoints/``, ``progress.csv`` (training log),
``evaluations.npz`` (returns, lengths and success rates on held-out resets) and ``train.json``
(settings, timing, final evaluation).
"""

from __future__ import annotations

import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from agents.sources import POSE_SOURCES, STARTS
from localization.cli._args import (
    UsageError,
    check_choice,
    check_env,
    check_existing_file,
    check_numbers,
    check_output_dir,
)
from localization.localizer import MEASUREMENTS
from localization.workflows.training import VEC_ENVS, TrainConfig, train_agent
from localization.wrappers import FILTERS

__all__ = ["Args", "check", "run"]

Args = TrainConfig


def check(args: Args) -> None:
    """Every option is valid (raises :class:`~localization.cli._args.UsageError`)."""
    check_choice("pose_source", args.pose_source, POSE_SOURCES)
    if args.pose_source != "oracle":
        check_existing_file("localizer", args.localizer)
    if args.measurement:
        check_choice("measurement", args.measurement, MEASUREMENTS)
    check_env(args)
    check_choice("start", args.start, STARTS)
    check_choice("vec_env", args.vec_env, VEC_ENVS)
    check_numbers(args, positive=("total_timesteps", "n_envs", "n_steps",
                                  "batch_size", "eval_freq", "eval_episodes", "checkpoint_freq",
                                  "threads"),
                  non_negative=("seed", "max_episode_steps", "uncertainty_penalty"))
    check_choice("filter", args.filter, FILTERS)
    try:
        args.kidnap_steps()
        args.source_options()
    except ValueError as err:
        option = "kidnap_at" if "kidnap_at" in str(err) else "filter"
        raise UsageError(option, str(err)) from None
    check_output_dir("out", args.out)


def run(args: Args) -> None:
    """Train (:func:`localization.workflows.training.train_agent`)."""
    train_agent(args)
