"""Workflows: the jobs built from the toolkit and the simulator (the one layer of
:mod:`localization` that imports :mod:`envs`).

- fitting a localizer for a city and closed-loop tracking (:mod:`.tracking`);
- the paper's experiment (:mod:`.experiment`);
- plots (:mod:`.plotting`).

Names load on first use (they import MuJoCo and matplotlib).
"""

from __future__ import annotations

from localization._lazy import lazy_names

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
__all__ = [
    "GSE_GRID",
    "MethodResult",
    "TrackResult",
    "covariance_ellipse",
    "evaluate_methods",
    "fit_city_localizer",
    "fit_city_noise",
    "fit_gse",
    "nees_band",
    "plot_track",
    "position_errors",
    "track_metrics",
    "track_route",
    "track_streets",
]

__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals())
