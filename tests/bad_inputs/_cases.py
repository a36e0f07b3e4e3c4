"""The bad-input table's shape: each case calls the API with one bad argument.

``Case(id, call, exc, match)``: ``call(ctx)`` must raise ``exc`` with a message matching
``match`` (a regex naming the argument). ``ctx`` gives lazily built, module-shared objects.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest


@dataclass(frozen=True)
class Case:
    id: str
    call: Callable[[Any], Any]
    exc: type[BaseException]
    match: str


def params(cases: list[Case]) -> list[Any]:
    """``pytest.param`` per case, with its id; ids must be unique."""
    ids = [c.id for c in cases]
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    return [pytest.param(c, id=c.id) for c in cases]


def check(case: Case, ctx: Any) -> None:
    with pytest.raises(case.exc, match=case.match) as info:
        case.call(ctx)
    assert "weights_only=False" not in str(info.value)  # never advise unpickling a file
