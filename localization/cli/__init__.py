"""``appearance-nav``: the command line (``appearance-nav <command> --help``).

Each command is a module of this package with a docstring (its ``--help`` text), an ``Args``
dataclass (its options, CleanRL style) and ``run(args) -> None``; :data:`COMMANDS` lists them.
A command module is imported only when its command runs, so ``--help`` is fast. A command
may define ``check(args) -> None``: it runs before ``run`` and raises
:class:`~localization.cli._args.UsageError` for a bad option, which is printed as argparse
prints its own errors (exit status 2) before any long work starts.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType

from localization.cli._args import UsageError, add_dataclass_args, to_dataclass

__all__ = ["COMMANDS", "main"]

#: command -> one-line summary (the module ``localization.cli.<command>`` implements it)
COMMANDS: dict[str, str] = {
    "demo": "the whole pipeline on the default city",
    "collect": "render a dataset of images and poses from the simulator",
    "fit": "fit a localizer on a city or on recorded images and poses",
    "predict": "estimate poses of recorded images with a saved localizer",
    "track": "closed-loop tracking of the pose belief",
    "train": "train a PPO agent on a pose source",
    "eval": "evaluate agents on pose sources",
    "bench": "benchmarks (JSON and markdown)",
    "reproduce": "the paper's experiment (Tables 1-2, Figs. 2-3)",
}


def _module(command: str) -> ModuleType:
    return importlib.import_module(f"{__name__}.{command}")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The top-level parser; with ``command``, that command's options are added too."""
    parser = argparse.ArgumentParser(
        prog="appearance-nav", description=__doc__.split("\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="command", required=True)
    for name, summary in COMMANDS.items():
        p = sub.add_parser(name, help=summary, description=summary,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        if name == command:
            mod = _module(name)
            p.description = mod.__doc__
            add_dataclass_args(p, mod.Args)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``appearance-nav`` with ``argv`` (None: ``sys.argv[1:]``); returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(command if command in COMMANDS else None)
    ns = parser.parse_args(argv)
    mod = _module(ns.command)
    try:
        args = to_dataclass(mod.Args, ns)
        if hasattr(mod, "check"):
            mod.check(args)
    except UsageError as err:
        _subparser(parser, ns.command).error(str(err))
    sub = _subparser(parser, ns.command)
    try:
        mod.run(args)
    except UsageError as err:  # an option found bad once the work has read its data
        sub.error(str(err))
    except (ValueError, OSError) as err:  # a bad file or value met while working
        sub.exit(1, f"{sub.prog}: error: {err}\n")
    return 0


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The parser of ``command`` (its usage line goes with its errors)."""
    for action in parser._subparsers._group_actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            return action.choices[command]
    return parser


if __name__ == "__main__":
    raise SystemExit(main())
