"""Shortest paths over the city's street graph (the map is known; the pose is not).

The street graph of :meth:`envs.scene.City.street_graph` has the intersections as nodes and
the straight street segments between them as edges. :class:`StreetPlanner` joins a start
and a goal to it (each at its nearest point on a street centreline) and runs Dijkstra
(``scipy.sparse.csgraph.shortest_path``), giving a polyline along the street centrelines.

Two kinds of plan:

- :meth:`StreetPlanner.plan` — the shortest street path, U-turns allowed (what a pedestrian
  would walk; used to score path lengths);
- :meth:`StreetPlanner.drive` — how a car drives it: after at most one turn on the spot at
  the start, it never U-turns on a street and takes every corner on a quarter circle of
  ``turn_radius``. These are the lanes the
  localizer is trained on (``envs.lanes``), so a robot driving this plan stays where its
  pose belief is reliable.
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import shortest_path

from localization._validation import check_array, check_real
from localization.geometry import Array

__all__ = ["BELIEF_OUTSIDE_FRACTION", "PlannedPath", "StreetPlanner", "check_city_point",
           "clamp_to_city", "path_length", "project_to_segments", "round_corners"]

#: how far (as a fraction of the city's side) a point may lie outside the city before it is
#: refused as a mistake (a belief may stray a little past the boundary wall; hundreds of
#: metres is a wrong unit or a wrong city)
OUTSIDE_FRACTION = 0.5
#: the same for a believed pose: a belief can coast off the map for metres (a kidnapped EKF
#: 12.8 m past the boundary of a 20 m city stopped the PPO training of stop 29); the
#: navigator plans such a belief from the nearest point of the city (``clamp_to_city``)
BELIEF_OUTSIDE_FRACTION = 5.0


def check_city_point(p: ArrayLike, name: str, city: Any, sizes: tuple[int, ...] = (2, 3),
                     outside_fraction: float = OUTSIDE_FRACTION) -> Array:
    """``p`` as a finite float64 point [x, y] (or pose [x, y, yaw]) near ``city``.

    Parameters
    ----------
    p : array-like of shape (k,), k in ``sizes``.
    name : the argument's name, for messages.
    city : envs.scene.City — its ``bounds`` and ``size``.
    sizes : the allowed lengths (2: a position, 3: a pose).

    Raises
    ------
    TypeError
        If ``p`` does not hold real numbers.
    ValueError
        If it has another shape, holds NaN/inf, or lies more than ``outside_fraction`` of the
        city's side outside the city.
    """
    a = check_array(p, name, ndim=1)
    if a.shape[0] not in sizes:
        what = " or ".join({2: "(2,) [x, y]", 3: "(3,) [x, y, yaw]"}[k] for k in sizes)
        raise ValueError(f"{name} must have shape {what}, got shape {a.shape}")
    lo, hi = city.bounds
    slack = outside_fraction * city.size
    if not (lo - slack <= a[0] <= hi + slack and lo - slack <= a[1] <= hi + slack):
        raise ValueError(f"{name} {a[:2]} is far outside the city [{lo}, {hi}]^2 "
                         f"(more than {slack:g} m): wrong units or another city?")
    return a


def clamp_to_city(p: Array, city: Any) -> Array:
    """A copy of the point or pose ``p`` with its position moved into the city's bounds."""
    lo, hi = city.bounds
    out = np.array(p, dtype=np.float64)
    out[:2] = np.clip(out[:2], lo, hi)
    return out



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


def round_corners(path: ArrayLike, radius: float, step: float = 0.05) -> Array:
    """Replace each corner of a polyline by a circular arc tangent to both legs.

    The arc radius is ``radius``, or less where a leg is too short to hold the tangent
    points (at most half of each leg is used). Arcs are sampled every ``step`` metres.
    """
    path = _dedupe(np.asarray(path, dtype=np.float64))
    if len(path) < 3 or radius <= 0:
        return path
    out = [path[0]]
    for i in range(1, len(path) - 1):
        a, b, c = path[i - 1], path[i], path[i + 1]
        u, v = b - a, c - b
        lu, lv = np.hypot(*u), np.hypot(*v)
        u, v = u / lu, v / lv
        turn = np.arctan2(u[0] * v[1] - u[1] * v[0], u @ v)  # signed, in (-pi, pi]
        if abs(turn) < 1e-6 or abs(turn) > np.pi - 1e-6:
            out.append(b)  # straight on, or a reversal: keep the corner
            continue
        tangent = min(radius * np.tan(abs(turn) / 2), 0.5 * lu, 0.5 * lv)
        r = tangent / np.tan(abs(turn) / 2)
        p0 = b - tangent * u
        centre = p0 + np.sign(turn) * r * np.array([-u[1], u[0]])
        phi0 = np.arctan2(*(p0 - centre)[::-1])
        n = max(int(np.ceil(r * abs(turn) / step)), 1)
        phis = phi0 + turn * np.linspace(0.0, 1.0, n + 1)
        out += list(centre + r * np.column_stack([np.cos(phis), np.sin(phis)]))
    out.append(path[-1])
    return _dedupe(np.array(out))


class StreetPlanner:
    """Plan street paths in a city.

    Parameters
    ----------
    city : envs.scene.City
        The known map: ``street_graph()`` gives the intersections and the street segments.
    turn_radius : float
        Radius (m) of the corners of :meth:`drive` plans.
    u_turn_cost : float
        Metres of driving a turn on the spot at the start of a :meth:`drive` plan is worth.

    Attributes
    ----------
    nodes : ndarray (k, 2) — intersection positions.
    edges : ndarray (e, 2) int — street segments as node pairs.
    """

    def __init__(self, city: Any, turn_radius: float = 0.8, u_turn_cost: float = 4.0) -> None:
        if not (hasattr(city, "street_graph") and hasattr(city, "bounds")):
            raise TypeError(f"city must be an envs.scene.City (env.unwrapped.city), "
                            f"got {type(city).__name__}")
        self.turn_radius = check_real(turn_radius, "turn_radius", low=0.0, low_open=True)
        self.u_turn_cost = check_real(u_turn_cost, "u_turn_cost", low=0.0)
        nodes, edges = city.street_graph()
        self.city = city
        self.nodes = np.asarray(nodes, dtype=np.float64)
        self.edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
        if len(self.edges) == 0:
            raise ValueError("the city's street graph has no edges")
        self._a, self._b = self.nodes[self.edges[:, 0]], self.nodes[self.edges[:, 1]]
        self._length = np.hypot(*(self._b - self._a).T)
        # directed edges: 2e is a -> b, 2e + 1 is b -> a
        self._tail = self.edges.ravel()                      # [a0, b0, a1, b1, ...]
        self._head = self.edges[:, ::-1].ravel()             # [b0, a0, b1, a1, ...]
        self._turns = self._directed_transitions()

    def _directed_transitions(self) -> coo_matrix:
        """Directed edge (x -> n) to (n -> w), w != x, weighted by the length of (n -> w)."""
        rows, cols, w = [], [], []
        for i, (x, n) in enumerate(zip(self._tail, self._head)):
            for j in np.flatnonzero(self._tail == n):
                if self._head[j] != x:
                    rows.append(i)
                    cols.append(int(j))
                    w.append(self._length[j // 2])
        return coo_matrix((w, (rows, cols)), shape=(2 * len(self.edges),) * 2)

    def nearest_street_point(self, p: ArrayLike) -> tuple[int, float, Array]:
        """The street segment nearest to ``p`` (2,): (edge index, t in [0, 1], foot point (2,))."""
        p = self._check_point(p, "point")
        t, foot, dist = project_to_segments(p, self._a, self._b)
        e = int(np.argmin(dist))
        return e, float(t[e]), foot[e]

    # ------------------------------------------------------------------ shortest path
    def plan(self, start: ArrayLike, goal: ArrayLike) -> Array:
        """Shortest path from ``start`` to ``goal`` along the streets, (p, 2) waypoints.

        The path is ``start``, its foot on the nearest street, the intersections Dijkstra
        chooses, the goal's foot on its nearest street, ``goal`` (consecutive duplicates
        removed). Start and goal on the same street segment give the direct path along it.
        """
        start, goal = self._check_point(start, "start"), self._check_point(goal, "goal")
        es, _, fs = self.nearest_street_point(start)
        eg, _, fg = self.nearest_street_point(goal)
        middle = [fs, fg] if es == eg else [fs, *self._via(es, fs, eg, fg), fg]
        return _dedupe(np.array([start, *middle, goal]))

    def _via(self, es: int, fs: Array, eg: int, fg: Array) -> list[Array]:
        """Intersections on the shortest path between two points on different segments."""
        k = len(self.nodes)
        s, g = k, k + 1  # the two feet as extra graph nodes
        rows, cols, w = list(self.edges[:, 0]), list(self.edges[:, 1]), list(self._length)
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

    # ------------------------------------------------------------------ car-like path
    def drive(self, pose: ArrayLike, goal: ArrayLike) -> Array:
        """How a car drives from ``pose`` [x, y, yaw] to ``goal``: (p, 2) waypoints.

        It joins the nearest street and drives along it, takes the shortest sequence of
        streets that needs no U-turn, and rounds every corner with a quarter circle of
        ``turn_radius`` (sampled every 5 cm). It sets off in the direction of its heading, or
        turns round on the spot first when that saves more than ``u_turn_cost`` metres.
        """
        pose = check_city_point(pose, "pose", self.city, sizes=(3,))
        goal = self._check_point(goal, "goal")
        es, _, fs = self.nearest_street_point(pose[:2])
        eg, _, fg = self.nearest_street_point(goal)
        forward = self._b[es] - self._a[es]
        behind = int(np.cos(pose[2]) * forward[0] + np.sin(pose[2]) * forward[1] < 0)
        best, best_cost = None, np.inf
        for d, penalty in ((2 * es + behind, 0.0), (2 * es + 1 - behind, self.u_turn_cost)):
            ahead = self.nodes[self._head[d]]
            if eg == es and (ahead - fs) @ (fg - fs) >= 0 \
                    and np.hypot(*(fg - fs)) <= np.hypot(*(ahead - fs)):
                corners = [fs, fg]  # the goal is on this street, ahead: straight there
            else:
                corners = [fs, *self._directed_via(d, eg, fg), fg]
            cost = path_length(corners) + penalty
            if cost < best_cost:
                best, best_cost = corners, cost
        return round_corners(np.array([pose[:2], *best, goal]), self.turn_radius)

    def _directed_via(self, d: int, eg: int, fg: Array) -> list[Array]:
        """Intersections of the shortest U-turn-free route from directed edge ``d`` to the goal."""
        m = 2 * len(self.edges)
        goal = m  # a virtual node: entering the goal's street at one end, stopping at fg
        g = self._turns.tocoo()
        rows, cols, w = list(g.row), list(g.col), list(g.data)
        for end, other in (tuple(self.edges[eg]), tuple(self.edges[eg][::-1])):
            for i in np.flatnonzero((self._head == end) & (self._tail != other)):
                rows.append(int(i))
                cols.append(goal)
                w.append(max(float(np.hypot(*(self.nodes[end] - fg))), 1e-9))
        graph = coo_matrix((w, (rows, cols)), shape=(m + 1, m + 1)).tocsr()
        dist, pred = shortest_path(graph, directed=True, indices=d, return_predecessors=True)
        if not np.isfinite(dist[goal]):
            raise ValueError("the goal is not reachable from the start without a U-turn")
        chain, node = [], pred[goal]
        while node != -9999 and node != d:
            chain.append(self._head[node])
            node = pred[node]
        return [self.nodes[self._head[d]]] + [self.nodes[n] for n in reversed(chain)]

    def _check_point(self, p: ArrayLike, name: str) -> Array:
        return check_city_point(p, name, self.city)[:2]


def _dedupe(path: Array, tol: float = 1e-6) -> Array:
    keep = np.r_[True, np.hypot(*np.diff(path, axis=0).T) > tol]
    return path[keep]


class PlannedPath:
    """A planned polyline resampled every ``step`` metres, with the robot's progress along it.

    Parameters
    ----------
    waypoints : (p, 2) from the start to the goal (e.g. :meth:`StreetPlanner.drive`).
    step : float — resampling step (m).
    search : float — how far ahead (m) of the current progress the robot is looked for
        (progress never goes back, so a path passing near itself is followed in order).
    """

    def __init__(self, waypoints: ArrayLike, step: float = 0.05, search: float = 3.0) -> None:
        w = check_array(waypoints, "waypoints", shape=(None, 2))
        if len(w) < 1:
            raise ValueError(f"waypoints must hold at least one point, got shape {w.shape}")
        step = check_real(step, "step", low=0.0, low_open=True)
        search = check_real(search, "search", low=0.0, low_open=True)
        pts = [w[0]]
        for a, b in pairwise(w):
            n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
            pts += list(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
        self.points = _dedupe(np.array(pts))
        self.step = float(step)
        self.search = max(int(search / step), 1)
        self.index = 0

    def update(self, xy: Array) -> int:
        """Advance the progress to the path point nearest ``xy`` (2,) within the search window."""
        window = np.arange(self.index, min(self.index + self.search, len(self.points)))
        self.index = int(window[np.argmin(np.hypot(*(self.points[window] - xy).T))])
        return self.index

    def ahead(self, distance: float) -> Array:
        """The path point about ``distance`` metres beyond the current progress (at most the goal)."""
        i = min(self.index + round(distance / self.step), len(self.points) - 1)
        return self.points[i]

    def distance_to(self, xy: Array) -> float:
        """Distance (m) from ``xy`` to the rest of the path."""
        return float(np.min(np.hypot(*(self.points[self.index:] - xy).T)))

    def remaining(self) -> float:
        """Path length (m) from the current progress to the goal."""
        return path_length(self.points[self.index:])
