"""Lazy public names for a package ``__init__`` (the pattern of ``gymnasium.wrappers``).

    __getattr__, __dir__ = lazy_names(__name__, {"Name": "submodule", ...}, globals())

``package.Name`` imports ``package.submodule`` on first access, so importing the package
stays light (no MuJoCo, no torch) until a heavy name is used.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["lazy_names"]


def lazy_names(package: str, table: dict[str, str], namespace: dict[str, Any]
               ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` resolving ``table``'s names (name -> submodule
    relative to ``package``) on first access; ``namespace`` is the package's ``globals()``."""

    def __getattr__(name: str) -> Any:
        if name in table:
            value = getattr(importlib.import_module(f"{package}.{table[name]}"), name)
            namespace[name] = value  # later lookups skip __getattr__
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__
