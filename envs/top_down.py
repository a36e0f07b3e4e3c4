"""The city seen from above as plain arrays: what maps drawn outside ``envs`` need.

:func:`top_down_map` turns a :class:`~envs.scene.City` into a :class:`TopDownMap` (numpy
arrays and floats, no MuJoCo): the buildings' footprints, heights and colours, and the
streets. ``AppearanceNavEnv.top_down_map()`` returns it, so code that may not import
``envs`` (``localization.wrappers``' ``render()``, the Rerun recordings) reads the city
duck-typed from ``env.unwrapped``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["TopDownMap", "top_down_map"]


@dataclass(frozen=True)
class TopDownMap:
    """A street-grid city from above (world frame, metres; the city is ``[lo, hi]^2``).

    Attributes
    ----------
    bounds : (float, float)
        ``(lo, hi)`` of both coordinates.
    footprints : (n, 4) float
        Building footprints ``[xmin, ymin, xmax, ymax]``.
    heights : (n,) float
        Building heights (m).
    colours : (n, 3) float
        Wall colours in [0, 1].
    landmarks : (n,) bool
        Whether a building is a tall, saturated landmark tower.
    street_centers : (k,) float
        Street centrelines: ``x = c`` and ``y = c`` for every ``c``.
    street_width : float
        Street width (m).
    """

    bounds: tuple[float, float]
    footprints: NDArray[np.float64]
    heights: NDArray[np.float64]
    colours: NDArray[np.float64]
    landmarks: NDArray[np.bool_]
    street_centers: NDArray[np.float64]
    street_width: float

    @property
    def streets(self) -> NDArray[np.float64]:
        """Street centrelines as (2k, 2, 2) segments ``[[x0, y0], [x1, y1]]`` (E-W, then N-S)."""
        c = self.street_centers
        lo, hi = float(c.min()), float(c.max())
        ew = [[[lo, y], [hi, y]] for y in c]
        ns = [[[x, lo], [x, hi]] for x in c]
        return np.array(ew + ns, dtype=np.float64).reshape(-1, 2, 2)


def top_down_map(city: Any) -> TopDownMap:
    """The :class:`TopDownMap` of a :class:`~envs.scene.City` (or a city with its attributes)."""
    buildings = list(city.buildings)
    heights = np.array([2.0 * b.half_size[2] for b in buildings], dtype=np.float64)
    colours = np.array([b.rgb for b in buildings], dtype=np.float64).reshape(-1, 3)
    landmarks = np.array([bool(b.landmark) for b in buildings], dtype=bool)
    lo, hi = city.bounds
    return TopDownMap(bounds=(float(lo), float(hi)),
                      footprints=np.asarray(city.footprints(), dtype=np.float64).reshape(-1, 4),
                      heights=heights, colours=colours, landmarks=landmarks,
                      street_centers=np.asarray(city.street_centers, dtype=np.float64).copy(),
                      street_width=float(city.street_width))
