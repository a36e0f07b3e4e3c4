"""Command-line options from a command's ``Args`` dataclass (CleanRL style), and the checks
that turn bad options into usage errors before any long work starts.

Every field becomes ``--field-name`` with its type, default and the ``help`` of its metadata;
a boolean field becomes a flag pair ``--field-name`` / ``--no-field-name``; a field whose
default is itself a dataclass (``default_factory``) becomes an option group whose options are
prefixed with the field name (``--env-steps`` for field ``steps`` of field ``env``).

A command's checks raise :class:`UsageError` naming the option; ``appearance-nav`` prints it
as argparse does (usage, ``error: argument --steps: ...``) and exits with status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, TypeVar

__all__ = [
    "UsageError",
    "add_dataclass_args",
    "check_choice",
    "check_choices",
    "check_env",
    "check_existing_file",
    "check_int_list",
    "check_non_negative",
    "check_numbers",
    "check_output_dir",
    "check_output_file",
    "check_positive",
    "parse_dataclass_args",
    "to_dataclass",
]

T = TypeVar("T")


class UsageError(ValueError):
    """A bad command-line option: ``option`` (a field name, ``_`` or ``-`` separated) and
    what is wrong with it."""

    def __init__(self, option: str, message: str) -> None:
        self.option = "--" + option.replace("_", "-").lstrip("-")
        super().__init__(f"argument {self.option}: {message}")


def _nested(f: dataclasses.Field) -> Any:
    """The default instance of a dataclass-valued field, else None."""
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        value = f.default_factory()  # type: ignore[misc]
        if dataclasses.is_dataclass(value):
            return value
    return None


def add_dataclass_args(parser: argparse.ArgumentParser | Any, cls: type, prefix: str = "",
                       defaults: Any = None) -> None:
    """Add one ``--<prefix>field-name`` option per field of the dataclass ``cls`` to
    ``parser``; ``defaults`` (an instance of ``cls``) overrides the fields' defaults."""
    for f in dataclasses.fields(cls):
        sub = _nested(f)
        if sub is not None:
            name = f.name.rstrip("_")  # a keyword field (``global_``) gives ``--global-...``
            group = parser.add_argument_group(f"{name} options", f.metadata.get("help"))
            add_dataclass_args(group, type(sub), f"{prefix}{name}_", sub)
            continue
        if f.metadata.get("help", "").startswith("internal:"):
            continue  # set by the program itself, not a user option
        default = getattr(defaults, f.name) if defaults is not None else f.default
        flag = "--" + (prefix + f.name).replace("_", "-")
        dest = prefix + f.name
        text = f"{f.metadata.get('help', '')} (default: {default!r})".replace("%", "%%")
        if isinstance(default, bool):
            parser.add_argument(flag, dest=dest, action=argparse.BooleanOptionalAction,
                                default=default, help=text)
        else:
            parser.add_argument(flag, dest=dest, type=type(default), default=default,
                                help=text)


def to_dataclass(cls: type[T], namespace: argparse.Namespace, prefix: str = "") -> T:
    """The ``cls`` instance holding the parsed options of ``namespace``."""
    values = vars(namespace)
    kwargs = {}
    for f in dataclasses.fields(cls):
        sub = _nested(f)
        if sub is not None:
            kwargs[f.name] = to_dataclass(type(sub), namespace, f"{prefix}{f.name.rstrip('_')}_")
        elif prefix + f.name in values:
            kwargs[f.name] = values[prefix + f.name]
    return cls(**kwargs)


def parse_dataclass_args(cls: type[T], doc: str | None, argv: list[str] | None = None,
                         prog: str | None = None) -> T:
    """Parse ``argv`` (None: ``sys.argv[1:]``) into an instance of the dataclass ``cls``
    (for thin scripts); ``doc`` is the ``--help`` description."""
    parser = argparse.ArgumentParser(prog=prog, description=doc,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_dataclass_args(parser, cls)
    return to_dataclass(cls, parser.parse_args(argv))


# ------------------------------------------------------------------------------- checks
def check_positive(option: str, value: float) -> None:
    """``value`` > 0 and finite."""
    if not (value > 0 and math.isfinite(value)):
        raise UsageError(option, f"must be positive, got {value!r}")


def check_non_negative(option: str, value: float) -> None:
    """``value`` >= 0 and finite."""
    if not (value >= 0 and math.isfinite(value)):
        raise UsageError(option, f"must be >= 0, got {value!r}")


def check_numbers(args: Any, positive: Iterable[str] = (), non_negative: Iterable[str] = (),
                  prefix: str = "") -> None:
    """Fields ``positive`` of ``args`` are > 0, fields ``non_negative`` >= 0 (all finite);
    ``prefix`` is prepended to the option names of the messages."""
    for name in positive:
        check_positive(prefix + name, getattr(args, name))
    for name in non_negative:
        check_non_negative(prefix + name, getattr(args, name))


def check_env(args: Any, prefix: str = "") -> None:
    """The env options a command has among ``scene_seed`` (>= 0), ``camera`` (registered),
    ``image_size`` (> 0), ``motion_noise`` (>= 0) and ``city_size`` (> 0, room for a block)."""
    from localization.workflows.sim import CAMERAS, check_city_layout

    names = {f.name for f in dataclasses.fields(args)}
    check_numbers(args, positive=sorted(names & {"image_size", "city_size"}),
                  non_negative=sorted(names & {"scene_seed", "motion_noise"}), prefix=prefix)
    if "city_size" in names:
        try:
            check_city_layout(args.city_size)
        except ValueError as err:
            raise UsageError(prefix + "city_size", str(err)) from None
    if "camera" in names:
        check_choice(prefix + "camera", args.camera, sorted(CAMERAS))


def check_choice(option: str, value: str, choices: Iterable[str]) -> None:
    """``value`` is one of ``choices``."""
    choices = tuple(choices)
    if value not in choices:
        raise UsageError(option, f"invalid choice {value!r} (choose from "
                                 f"{', '.join(map(repr, choices))})")


def check_choices(option: str, value: str, choices: Iterable[str]) -> list[str]:
    """``value`` is a comma-separated, non-empty list of ``choices``; returns the list."""
    choices = tuple(choices)
    items = [s.strip() for s in value.split(",")]
    if not value.strip() or "" in items:
        raise UsageError(option, f"expected a comma-separated list of "
                                 f"{', '.join(map(repr, choices))}, got {value!r}")
    bad = [s for s in items if s not in choices]
    if bad:
        raise UsageError(option, f"invalid choice(s) {', '.join(map(repr, bad))} (choose from "
                                 f"{', '.join(map(repr, choices))})")
    return items


def check_int_list(option: str, value: str, minimum: int = 0) -> list[int]:
    """``value`` is a comma-separated, non-empty list of integers >= ``minimum``."""
    try:
        items = [int(s) for s in value.split(",")]
    except ValueError:
        raise UsageError(option, f"expected comma-separated integers, got {value!r}") from None
    bad = [i for i in items if i < minimum]
    if bad:
        raise UsageError(option, f"every value must be >= {minimum}, got {bad[0]}")
    return items


def check_existing_file(option: str, path: str) -> None:
    """``path`` names an existing file."""
    p = Path(path)
    if not path or not p.exists():
        raise UsageError(option, f"no such file: {path!r}")
    if not p.is_file():
        raise UsageError(option, f"not a file: {path!r}")


def _writable_parent(option: str, folder: Path, path: str) -> None:
    """The nearest existing ancestor of ``folder`` is a writable directory."""
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise UsageError(option, f"cannot write {path!r}: {str(probe)!r} is a file")
    try:  # a real probe: os.access says yes to root even on read-only file systems
        with tempfile.NamedTemporaryFile(dir=probe):
            pass
    except OSError as err:
        raise UsageError(option, f"cannot write {path!r}: {str(probe)!r} is not writable "
                                 f"({err.strerror})") from None


def check_output_dir(option: str, path: str) -> None:
    """``path`` is (or can be created as) a writable directory."""
    if not path:
        raise UsageError(option, "must name a folder, got ''")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UsageError(option, f"{path!r} exists and is not a folder")
    _writable_parent(option, p.resolve(), path)


def check_output_file(option: str, path: str, suffixes: Sequence[str] = ()) -> None:
    """``path`` can be written as a file (not an existing folder; its folder can be created);
    with ``suffixes``, it ends in one of them."""
    p = Path(path)
    if not path or path.endswith(("/", os.sep)) or (p.exists() and p.is_dir()):
        raise UsageError(option, f"{path!r} is a folder; expected a file path")
    if suffixes and p.suffix not in suffixes:
        raise UsageError(option, f"{path!r} must end in {' or '.join(suffixes)}")
    _writable_parent(option, p.resolve().parent, path)
