"""Reproduce section V of the paper (Tables 1-2, Figs. 2-3) on the simulated city.

    appearance-nav reproduce            # full run, <= 30 min on 2 cores
    appearance-nav reproduce --quick    # <= 3 min: small data, fewer features

For each camera of city ``--scene-seed`` it collects n images along the robot's closed route
and n at random 3-DoF poses, splits each 70/30 at random, and writes to ``--out``: Table 1
(intrinsic dimension of the route images), Table 2 (position RRMSE of GSE, KNR and kNN
retrieval for every feature extractor; the random 3-DoF table adds the heading RMSE), Figs. 2-3
(reduce-reconstruct and tangent images), ``tables.md``, ``results.json`` and PNGs.
"""

from __future__ import annotations

import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from localization.cli._args import (
    UsageError,
    check_choices,
    check_env,
    check_numbers,
    check_output_dir,
)
from localization.workflows.extractors import EXTRACTORS
from localization.workflows.paper import PaperConfig, run_paper
from localization.workflows.sim import CAMERAS

__all__ = ["Args", "check", "run"]

Args = PaperConfig

#: fewest images per data set accepted (a floor for a meaningful 70/30 split with CV folds)
MIN_IMAGES = 100


def check(args: Args) -> None:
    """Every option is valid (raises :class:`~localization.cli._args.UsageError`)."""
    check_choices("cameras", args.cameras, sorted(CAMERAS))
    check_env(args)
    check_numbers(args, positive=("n", "n_components", "figure_components", "ground_range",
                                  "intrinsic_samples", "num_threads"),
                  non_negative=("seed", "split_seed", "pixel_smooth"))
    if args.n < MIN_IMAGES:
        raise UsageError("n", f"must be >= {MIN_IMAGES} (images per data set), got {args.n}")
    if args.imagenet_image_size < 32:
        raise UsageError("imagenet_image_size", f"must be >= 32 (the network's smallest "
                         f"input), got {args.imagenet_image_size}")
    if args.cv < 2:
        raise UsageError("cv", f"must be >= 2 (cross-validation folds), got {args.cv}")
    check_choices("features", args.features, EXTRACTORS)
    check_choices("datasets", args.datasets, ("route", "random"))
    check_output_dir("out", args.out)


def run(args: Args) -> None:
    """Run the experiment (:func:`localization.workflows.paper.run_paper`)."""
    run_paper(args)
