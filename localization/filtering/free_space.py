"""Free poses from a map's street graph, for a global start of the particle belief.

The map an agent plans on (``city.street_graph()``: intersections and the straight streets
between them) is all a global start needs: poses along the streets, heading along the
street either way. Numpy only, so the filtering layer never imports the simulator.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array, wrap_angle

__all__ = ["city_sampler", "street_graph_sampler"]


def street_graph_sampler(nodes: ArrayLike, edges: ArrayLike, lateral: float = 0.6,
                         heading: float = 0.4) -> Callable[[int, np.random.Generator], Array]:
    """``sample_free(n, rng) -> (n, 3)``: poses uniform along the street segments.

    Parameters
    ----------
    nodes : array_like (k, 2)
        Intersection positions.
    edges : array_like (e, 2) of int
        Pairs of node indices joined by a straight street.
    lateral : float
        Largest sideways offset from the street's centre line (m), uniform.
    heading : float
        Largest heading offset from the street's direction (rad), uniform; the direction
        along the street is drawn either way.
    """
    P = np.asarray(nodes, dtype=np.float64)
    E = np.asarray(edges, dtype=np.int64)
    if P.ndim != 2 or P.shape[1] != 2 or len(P) < 2 or not np.all(np.isfinite(P)):
        raise ValueError(f"nodes must be finite (k, 2) positions, k >= 2, got {P.shape}")
    if E.ndim != 2 or E.shape[1] != 2 or len(E) < 1 or E.min() < 0 or E.max() >= len(P):
        raise ValueError(f"edges must be (e, 2) node indices in [0, {len(P)}), got {E.shape}")
    a, b = P[E[:, 0]], P[E[:, 1]]
    length = np.hypot(*(b - a).T)
    if not np.all(length > 0):
        raise ValueError("edges must join distinct nodes")
    p = length / length.sum()
    direction = np.arctan2(*(b - a).T[::-1])

    def sample_free(n: int, rng: np.random.Generator) -> Array:
        i = rng.choice(len(E), size=n, p=p)
        s = rng.uniform(0.0, 1.0, n)[:, None]
        yaw = direction[i] + np.pi * rng.integers(0, 2, n)
        side = rng.uniform(-lateral, lateral, n)
        xy = a[i] + s * (b[i] - a[i]) + side[:, None] * np.column_stack([-np.sin(yaw),
                                                                           np.cos(yaw)])
        return np.column_stack([xy, wrap_angle(yaw + rng.uniform(-heading, heading, n))])

    return sample_free


def city_sampler(city: Any) -> Callable[[int, np.random.Generator], Array]:
    """:func:`street_graph_sampler` of a map with ``street_graph()`` (e.g. ``env.unwrapped.city``)."""
    street_graph = getattr(city, "street_graph", None)
    if not callable(street_graph):
        raise TypeError(f"the map must have street_graph() (nodes, edges), got "
                        f"{type(city).__name__}")
    return street_graph_sampler(*street_graph())
