"""Shortest paths over the city's street graph (the map is known; the pose is not).

The street graph of :meth:`envs.scene.City.street_graph` has the intersections as nodes and
the straight street segments between them as edges. :class:`StreetPlanner` joins a start
and a goal to it (each at its nearest point on a street centreline) and runs Dijkstra
(``scipy.sparse.csgraph.shortest_path``) over the result, giving a polyline along the
street centrelines from the start to the goal.
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

__all__ = ["PlannedPath", "StreetPlanner", "path_length", "project_to_segments"]

Array = NDArray[np.float64]


def project_to_segments(p: Array, a: Array, b: Array) -> tuple[Array, Array, Array]:
    """Project the point ``p`` (2,) on the segments ``a[i] -> b[i]`` (s, 2).

    Returns
    -------
    t : (s,) position of the foot along each segment in [0, 1]
    foot : (s, 2) the nearest point of each segment
    dist : (s,) distance from ``p`` to each segment
    """
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12),
                0.0, 1.0)
    foot = a + t[:, None] * ab
    return t, foot, np.hypot(*(foot - p).T)


def path_length(path: ArrayLike) -> float:
    """Length in metres of a polyline (p, 2)."""
    path = np.asarray(path, dtype=np.float64)
    return float(np.sum(np.hypot(*np.diff(path, axis=0).T))) if len(path) > 1 else 0.0


class StreetPlanner:
    """Plan shortest street paths in a city.

    Parameters
    ----------
    city : envs.scene.City
        The known map: ``street_graph()`` gives the intersections and the street segments.

    Attributes
    ----------
    nodes : ndarray (k, 2) — intersection positions.
    edges : ndarray (e, 2) int — street segments as node pairs.
    """

    def __init__(self, city: Any) -> None:
        nodes, edges = city.street_graph()
        self.city = city
        self.nodes = np.asarray(nodes, dtype=np.float64)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        if len(self.edges) == 0:
            raise ValueError("the city's street graph has no edges")
        self._a, self._b = self.nodes[self.edges[:, 0]], self.nodes[self.edges[:, 1]]

    def nearest_street_point(self, p: ArrayLike) -> tuple[int, float, Array]:
        """The street segment nearest to ``p`` (2,): (edge index, t in [0, 1], foot point (2,))."""
        p = self._check_point(p, "point")
        t, foot, dist = project_to_segments(p, self._a, self._b)
        e = int(np.argmin(dist))
        return e, float(t[e]), foot[e]

    def plan(self, start: ArrayLike, goal: ArrayLike) -> Array:
        """Shortest path from ``start`` to ``goal`` along the streets, (p, 2) waypoints.

        The path is ``start``, its foot on the nearest street, the intersections Dijkstra
        chooses, the goal's foot on its nearest street, ``goal`` (consecutive duplicates
        removed). Start and goal on the same street segment give the direct path along it.
        """
        start, goal = self._check_point(start, "start"), self._check_point(goal, "goal")
        es, ts, fs = self.nearest_street_point(start)
        eg, tg, fg = self.nearest_street_point(goal)
        if es == eg:
            middle = [fs, fg]
        else:
            middle = [fs, *self._via(es, ts, fs, eg, tg, fg), fg]
        return _dedupe(np.array([start, *middle, goal]))

    def _via(self, es: int, ts: float, fs: Array, eg: int, tg: float, fg: Array) -> list[Array]:
        """Intersections on the shortest path between two points on different segments."""
        k = len(self.nodes)
        s, g = k, k + 1  # the two feet as extra graph nodes
        rows, cols, w = [], [], []
        for i, j in self.edges:
            rows.append(i)
            cols.append(j)
            w.append(float(np.hypot(*(self.nodes[i] - self.nodes[j]))))
        for extra, e, foot in ((s, es, fs), (g, eg, fg)):
            for node in self.edges[e]:
                rows.append(extra)
                cols.append(int(node))
                w.append(max(float(np.hypot(*(self.nodes[node] - foot))), 1e-9))
        graph = coo_matrix((w, (rows, cols)), shape=(k + 2, k + 2)).tocsr()
        _, pred = shortest_path(graph, directed=False, indices=s, return_predecessors=True)
        if pred[g] < 0:
            raise ValueError("the goal is not reachable from the start on the street graph")
        chain, node = [], pred[g]
        while node != s:
            chain.append(node)
            node = pred[node]
        return [self.nodes[n] for n in reversed(chain)]

    @staticmethod
    def _check_point(p: ArrayLike, name: str) -> Array:
        p = np.asarray(p, dtype=np.float64).reshape(-1)[:2]
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise ValueError(f"{name} must be a finite [x, y] (or pose [x, y, yaw]), got {p}")
        return p


def _dedupe(path: Array, tol: float = 1e-6) -> Array:
    keep = np.r_[True, np.hypot(*np.diff(path, axis=0).T) > tol]
    return path[keep]


class PlannedPath:
    """A planned polyline resampled every ``step`` metres, with the robot's progress along it.

    Parameters
    ----------
    waypoints : (p, 2) from the start to the goal (e.g. :meth:`StreetPlanner.plan`).
    step : float — resampling step (m).
    search : float — how far ahead (m) of the current progress the robot is looked for
        (progress never goes back, so a path passing near itself is followed in order).
    """

    def __init__(self, waypoints: ArrayLike, step: float = 0.05, search: float = 3.0) -> None:
        w = np.asarray(waypoints, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != 2 or len(w) < 1 or not np.all(np.isfinite(w)):
            raise ValueError(f"waypoints must be finite with shape (p, 2), p >= 1, got {w.shape}")
        pts = [w[0]]
        for a, b in pairwise(w):
            n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
            pts += list(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
        self.points = np.array(pts)
        self.step = float(step)
        self.search = max(int(search / step), 1)
        self.index = 0

    def update(self, xy: Array) -> int:
        """Advance the progress to the path point nearest ``xy`` (2,) within the search window."""
        window = np.arange(self.index, min(self.index + self.search, len(self.points)))
        self.index = int(window[np.argmin(np.hypot(*(self.points[window] - xy).T))])
        return self.index

    def ahead(self, distance: float) -> Array:
        """The path point ``distance`` metres beyond the current progress (the goal at most)."""
        i = min(self.index + round(distance / self.step), len(self.points) - 1)
        return self.points[i]

    def distance_to(self, xy: Array) -> float:
        """Distance (m) from ``xy`` to the rest of the path."""
        return float(np.min(np.hypot(*(self.points[self.index:] - xy).T)))

    def remaining(self) -> float:
        """Path length (m) from the current progress to the goal."""
        return (len(self.points) - 1 - self.index) * self.step
