"""Command-line options from a script's ``Args`` dataclass (CleanRL style).

Every field becomes ``--field-name`` with its type, default and the ``help`` of its metadata;
a boolean field becomes a flag pair ``--field-name`` / ``--no-field-name``.
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import TypeVar

T = TypeVar("T")


def parse_dataclass_args(cls: type[T], doc: str | None, argv: list[str] | None = None) -> T:
    """Parse ``argv`` (None: ``sys.argv[1:]``) into an instance of the dataclass ``cls``;
    ``doc`` (the script's docstring) is the ``--help`` description."""
    parser = argparse.ArgumentParser(description=doc,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        text = f"{f.metadata.get('help', '')} (default: {f.default!r})"
        if isinstance(f.default, bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default,
                                help=text)
        else:
            parser.add_argument(flag, type=type(f.default), default=f.default, help=text)
    return cls(**vars(parser.parse_args(argv)))
