"""The main job (``make demo``): the whole pipeline on the default city.

    appearance-nav demo                 # default city (scene seed 0), results/ as output
    appearance-nav demo --scene-seed 3 --lanes route
    appearance-nav demo --rerun results/demo.rrd     # then: rerun results/demo.rrd

Stages: (1) drive the route once: ``<out>/route_dataset.npz`` and ``<out>/demo_route.png``;
(2) fit the localizer (features + GSE + noise model) on images around the driving lanes:
``<out>/localizer.npz``; (3) closed-loop tracking of each measurement model against dead
reckoning: ``<out>/track_<model>.png``, ``<out>/demo.md``, the same route at dusk on the
daylight localizer (``--dusk PRESET``, ``''`` to skip), the kidnapping stage and the
episode video ``<out>/episode.mp4`` (the scripted agent on the particle belief through a
kidnap; ``--rerun FILE.rrd`` also records it for the Rerun viewer, ``rerun FILE.rrd``);
(4) the scripted agent on every pose source: ``<out>/demo_agents/agents.md``. Everything also in ``<out>/demo.json``.
"""

from __future__ import annotations

# isort: split
from localization.cli._args import check_choice, check_env, check_numbers, check_output_dir
from localization.cli._rerun import check_rerun
from localization.workflows.demo import DemoConfig, run_demo
from localization.workflows.sim import CONDITION_NAMES, LANE_SETS

__all__ = ["Args", "check", "run"]

Args = DemoConfig


def check(args: Args) -> None:
    """Every option is valid (raises :class:`~localization.cli._args.UsageError`)."""
    check_env(args)
    check_numbers(args, positive=("n_route", "strip", "n_train", "n_drive", "steps"),
                  non_negative=("seed", "start", "episodes"))
    check_choice("lanes", args.lanes, LANE_SETS)
    if args.dusk:
        check_choice("dusk", args.dusk, CONDITION_NAMES)
    check_output_dir("out", args.out)
    check_rerun(args.rerun)


def run(args: Args) -> None:
    """Run the demo (:func:`localization.workflows.demo.run_demo`)."""
    run_demo(args)
