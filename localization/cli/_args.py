"""Command-line options from a command's ``Args`` dataclass (CleanRL style).

Every field becomes ``--field-name`` with its type, default and the ``help`` of its metadata;
a boolean field becomes a flag pair ``--field-name`` / ``--no-field-name``.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any


def add_dataclass_args(parser: argparse.ArgumentParser, cls: type) -> None:
    """Add one ``--field-name`` option per field of the dataclass ``cls`` to ``parser``."""
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        text = f"{f.metadata.get('help', '')} (default: {f.default!r})"
        if isinstance(f.default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default,
                                help=text)
        else:
            parser.add_argument(flag, type=type(f.default), default=f.default, help=text)


def to_dataclass(cls: type, namespace: argparse.Namespace) -> Any:
    """The ``cls`` instance holding the parsed options of ``namespace``."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in vars(namespace).items() if k in names})
