"""Driving lanes of the street graph: where a robot driving the streets can be.

A lane is a directed street segment (heading along the street) or a turn arc at an
intersection (a quarter circle of radius ``turn_radius`` joining an incoming and an
outgoing street, the heading turning with it). ``lanes="streets"`` gives every street in
both directions and every left and right turn; ``lanes="route"`` only the segments and
turns of the city's loop ``city.route()`` in its driving direction.

:func:`lane_poses` samples poses around the lanes: a point on a lane (chosen by length,
turns weighted up, see below), shifted sideways by up to ``lateral`` metres and turned by
up to ``heading`` radians, kept if it is ``margin`` away from buildings. :func:`street_tour`
draws a random drive over the street graph (intersections to visit, no U-turns). Images change much
faster with heading than with position (at 64 px a 0.1 rad turn changes the image about as
much as a 1 m drive), so a turn arc, which sweeps pi/2 of heading in ~1.3 m, is sampled as
if it were ``sqrt(1 + (turn_weight / turn_radius)^2)`` times longer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from envs.motion_model import wrap_angle
from localization._validation import check_choice, check_int, check_real

LANE_SETS = ("streets", "route")


@dataclass(frozen=True)
class Lane:
    """One lane: a straight segment ``start -> end`` or a turn arc.

    ``turn`` is 0 for a segment, +1 (left, counter-clockwise) or -1 (right) for an arc of
    radius ``radius`` starting at ``start`` with heading ``yaw0``.
    """

    start: NDArray[np.float64]
    end: NDArray[np.float64]
    yaw0: float
    turn: int = 0
    radius: float = 0.0

    @property
    def length(self) -> float:
        if self.turn == 0:
            return float(np.hypot(*(self.end - self.start)))
        return 0.5 * np.pi * self.radius

    @property
    def curvature(self) -> float:
        """Signed curvature (1/m): 0 on a segment, +-1/radius on an arc."""
        return 0.0 if self.turn == 0 else self.turn / self.radius

    def pose(self, t: float) -> NDArray[np.float64]:
        """Pose ``[x, y, yaw]`` at fraction ``t`` in [0, 1] of the lane."""
        if self.turn == 0:
            return np.array([*(self.start + t * (self.end - self.start)), self.yaw0])
        n = self.turn * np.array([-np.sin(self.yaw0), np.cos(self.yaw0)])  # towards the centre
        centre = self.start + self.radius * n
        a = self.turn * 0.5 * np.pi * t
        c, s = np.cos(a), np.sin(a)
        v = self.start - centre
        return np.array([*(centre + [c * v[0] - s * v[1], s * v[0] + c * v[1]]),
                         float(wrap_angle(self.yaw0 + a))])


def _turn(node: NDArray[np.float64], d_in: NDArray[np.float64], d_out: NDArray[np.float64],
          radius: float) -> Lane | None:
    """The arc from heading d_in to d_out at an intersection, None unless they are perpendicular."""
    cross = float(d_in[0] * d_out[1] - d_in[1] * d_out[0])
    if abs(cross) < 0.5:
        return None
    start = node - radius * d_in
    return Lane(start, node + radius * d_out, float(np.arctan2(d_in[1], d_in[0])),
                int(np.sign(cross)), radius)


def street_lanes(city: Any, lanes: str = "streets", turn_radius: float = 0.8) -> list[Lane]:
    """The lanes of ``city`` (see the module docstring).

    Raises
    ------
    ValueError
        For an unknown lane set or a non-positive turn radius.
    """
    check_choice(lanes, "lanes", LANE_SETS)
    turn_radius = check_real(turn_radius, "turn_radius", low=0.0, low_open=True)
    out: list[Lane] = []

    def segment(a: NDArray[np.float64], b: NDArray[np.float64]) -> None:
        d = b - a
        out.append(Lane(a, b, float(np.arctan2(d[1], d[0]))))

    if lanes == "route":
        wp = np.asarray(city.route(), dtype=np.float64)
        for i in range(len(wp)):
            a, b, c = wp[i - 1], wp[i], wp[(i + 1) % len(wp)]
            segment(b, c)
            arc = _turn(b, (b - a) / np.hypot(*(b - a)), (c - b) / np.hypot(*(c - b)), turn_radius)
            if arc is not None:
                out.append(arc)
        return out
    nodes, edges = city.street_graph()
    neighbours: dict[int, list[int]] = {i: [] for i in range(len(nodes))}
    for i, j in edges:
        segment(nodes[i], nodes[j])
        segment(nodes[j], nodes[i])
        neighbours[i].append(j)
        neighbours[j].append(i)
    for i, nb in neighbours.items():
        dirs = [(nodes[j] - nodes[i]) / np.hypot(*(nodes[j] - nodes[i])) for j in nb]
        for d_from in dirs:  # arriving from that neighbour: heading -d_from
            for d_out in dirs:
                arc = _turn(nodes[i], -d_from, d_out, turn_radius)
                if arc is not None:
                    out.append(arc)
    return out


def lane_poses(city: Any, n: int, rng: np.random.Generator, lanes: str = "streets",
               lateral: float = 0.3, heading: float = 0.2, turn_radius: float = 0.8,
               turn_weight: float = 8.0, margin: float = 0.32,
               ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sample n poses around the lanes of ``city`` (see the module docstring).

    Parameters
    ----------
    city : envs.scene.City
    n : int
    rng : numpy.random.Generator
    lanes : {"streets", "route"}
    lateral : float
        Largest sideways offset from the lane (m), uniform.
    heading : float
        Largest heading offset from the lane direction (rad), uniform.
    turn_radius : float
        Radius of the turn arcs (m).
    turn_weight : float
        Metres of lane a radian of turning counts as (0: sample by length alone).
    margin : float
        Clearance to buildings (m).

    Returns
    -------
    poses : (n, 3) float64 ``[x, y, yaw]``
    curvature : (n,) float64
        Signed curvature (1/m) of the lane each pose came from (0 on straight segments).
    """
    n = check_int(n, "n", low=1)
    for name, value in (("lateral", lateral), ("heading", heading), ("turn_weight", turn_weight),
                        ("margin", margin)):
        check_real(value, name, low=0.0)
    check_real(turn_radius, "turn_radius", low=0.0, low_open=True)
    pieces = street_lanes(city, lanes, turn_radius)
    weight = np.array([p.length * (1.0 if p.turn == 0 else
                                   np.sqrt(1.0 + (turn_weight / turn_radius) ** 2))
                       for p in pieces])
    cum = np.concatenate([[0.0], np.cumsum(weight)])
    poses, curvature = [], []
    for _ in range(1000 * n):
        if len(poses) == n:
            break
        k = int(np.searchsorted(cum, rng.uniform(0.0, cum[-1]), side="right") - 1)
        p = pieces[k].pose(rng.uniform())
        off, turn = rng.uniform(-lateral, lateral), rng.uniform(-heading, heading)
        p[:2] += off * np.array([-np.sin(p[2]), np.cos(p[2])])
        p[2] = wrap_angle(p[2] + turn)
        if city.is_free(p[0], p[1], margin):
            poses.append(p)
            curvature.append(pieces[k].curvature)
    if len(poses) < n:
        raise RuntimeError(f"found only {len(poses)} free lane poses of {n} (margin {margin} m, "
                           f"lateral offset {lateral} m): streets too narrow for them")
    return np.array(poses), np.array(curvature)


def street_tour(city: Any, length: float, rng: np.random.Generator) -> NDArray[np.float64]:
    """A random drive over the street graph: intersections (p, 2) to visit in order.

    It starts at a random intersection, goes to a random neighbour, then at every
    intersection takes a random street other than the one it came from (no U-turns, like
    the lanes), until the polyline is at least ``length`` metres long. Streets are driven
    in both directions and every turn is possible, so a long tour covers the whole city.

    Raises
    ------
    ValueError
        For a non-positive length.
    """
    length = check_real(length, "length", low=0.0, low_open=True)
    nodes, edges = city.street_graph()
    neighbours: dict[int, list[int]] = {i: [] for i in range(len(nodes))}
    for i, j in edges:
        neighbours[i].append(j)
        neighbours[j].append(i)
    prev, node = -1, int(rng.integers(len(nodes)))
    tour, total = [node], 0.0
    while total < length:
        options = [j for j in neighbours[node] if j != prev] or neighbours[node]
        prev, node = node, options[int(rng.integers(len(options)))]
        total += float(np.hypot(*(nodes[node] - nodes[prev])))
        tour.append(node)
    return np.asarray(nodes[tour], dtype=np.float64)
