"""Workflows: the jobs built from the toolkit and the simulator (the one layer of
:mod:`localization` that imports :mod:`envs`).

- fitting a localizer for a city and closed-loop tracking (:mod:`.tracking`);
- the paper's experiment (:mod:`.experiment`);
- plots (:mod:`.plotting`).

Names load on first use (they import MuJoCo and matplotlib).
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "TrackResult": "tracking",
    "fit_city_localizer": "tracking",
    "fit_city_noise": "tracking",
    "nees_band": "tracking",
    "track_metrics": "tracking",
    "track_route": "tracking",
    "track_streets": "tracking",
    "GSE_GRID": "experiment",
    "MethodResult": "experiment",
    "evaluate_methods": "experiment",
    "fit_gse": "experiment",
    "position_errors": "experiment",
    "covariance_ellipse": "plotting",
    "plot_track": "plotting",
}
__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
