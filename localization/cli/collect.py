"""Render a dataset of camera images and true poses from AppearanceNav-v0 into an ``.npz``.

    appearance-nav collect --mode grid --n 2000 --out data/grid_seed0.npz
    appearance-nav collect --mode route --n 3000 --motion-noise 0.05 --camera fisheye
    appearance-nav collect --mode lanes --n 4000 --conditions random   # a look per image
    appearance-nav collect --mode random --n 20000 --workers 2          # 2 local processes
    appearance-nav collect --n 100000 --workers 64 --ray-address auto   # a Ray cluster

The file holds ``images`` (n, H, W, 3) uint8, ``poses`` (n, 3) float64 ``[x, y, yaw]`` and
``meta`` (a JSON string with these options); read it with ``envs.load_dataset``.

The samples are collected in fixed slices of 500 (one task each; "route", one drive, is one
task) in this process, on ``--workers`` local processes, or as Ray tasks on the cluster at
``--ray-address`` (the ``distributed`` extra): the arrays are the same for any
``--workers``.
"""

from __future__ import annotations

# isort: split
from localization.cli._args import check_choice, check_env, check_numbers, check_output_file
from localization.cli._parallel import check_parallel
from localization.workflows.collect import CollectConfig, collect_out_path, collect_to_file
from localization.workflows.sim import CONDITION_NAMES, MODES

__all__ = ["Args", "check", "run"]

Args = CollectConfig


def check(args: Args) -> None:
    """Every option is valid, and ``--out`` can be written (before anything is collected)."""
    check_choice("mode", args.mode, MODES)
    check_choice("conditions", args.conditions, CONDITION_NAMES)
    check_env(args)
    check_numbers(args, positive=("n", "height", "width", "n_headings"),
                  non_negative=("seed",))
    check_parallel(args)
    if args.out:
        check_output_file("out", args.out)
    check_output_file("out", str(collect_out_path(args)))


def run(args: Args) -> None:
    """Collect and save (:func:`localization.workflows.collect.collect_to_file`)."""
    collect_to_file(args)
