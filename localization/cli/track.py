"""Closed-loop tracking on the pose belief: drive the city's route with a pure-pursuit
controller on the belief mean, for each measurement model, against dead reckoning.

    appearance-nav track                               # default city, fits a localizer
    appearance-nav track --localizer results/localizer.npz --steps 2000
    appearance-nav track --localizer results/localizer.npz --rerun results/track.rrd

For each measurement model and start point it writes ``<out>/track_<model>_<start>.png``
(top-down map with the true path, the belief with 2-sigma ellipses and the dead-reckoning
path; error over time; NEES and NIS), and ``<out>/track.json`` / ``<out>/track.md`` with the
scores (position RMSE of the belief and of dead reckoning over the same run, their ratio,
mean NEES and its chi-square band over the runs, NIS, acceptance, time per step).
``--rerun FILE.rrd`` (the ``viewer`` extra) also records every run, step by step, for the
Rerun viewer (``rerun FILE.rrd``).
"""

from __future__ import annotations

import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from localization.cli._args import (
    check_choice,
    check_choices,
    check_env,
    check_existing_file,
    check_int_list,
    check_numbers,
    check_output_dir,
)
from localization.cli._rerun import check_rerun
from localization.localizer import MEASUREMENTS
from localization.workflows.sim import LANE_SETS
from localization.workflows.track_runs import TrackConfig, run_tracking

__all__ = ["Args", "check", "run"]

Args = TrackConfig


def check(args: Args) -> None:
    """Every option is valid (raises :class:`~localization.cli._args.UsageError`)."""
    check_env(args)
    if args.localizer:
        check_existing_file("localizer", args.localizer)
    check_choice("lanes", args.lanes, LANE_SETS)
    check_numbers(args, positive=("n_train", "n_drive", "steps"), non_negative=("seed",))
    check_choices("measurements", args.measurements, MEASUREMENTS)
    check_int_list("starts", args.starts, minimum=0)
    check_output_dir("out", args.out)
    check_rerun(args.rerun)


def run(args: Args) -> None:
    """Track (:func:`localization.workflows.track_runs.run_tracking`)."""
    run_tracking(args)
