"""Drives that leave the lanes: weaving across the street, U-turns, turning on the spot at
corners, starting off the lanes at any heading. For closed-loop tests of a localizer trained
on the whole street surface (:mod:`envs.coverage`).

:func:`off_lane_waypoints` draws a random walk over the street graph (like
:func:`envs.lanes.street_tour`), but the robot does not keep to a lane: between two
intersections it weaves from one side of the street to the other (waypoints every
``spacing`` metres, alternately left and right of the centreline by up to ``weave`` metres);
at each intersection it aims at a random point of the intersection square; with probability
``u_turn`` a street is driven only part way and the robot turns back (a U-turn in the
street), and at an intersection it may also go back the way it came. Every waypoint lies on
the street surface ``margin`` metres clear of buildings, and consecutive waypoints lie in one
street strip (a convex band), so the straight line between them is clear too.

:class:`OffLanePilot` drives through the waypoints like a wheeled robot, not a car: when
the next waypoint is more than ``turn_in_place`` radians off its heading it stops and turns
on the spot (until it is within a fifth of that), else it drives the arc through the
waypoint (pure pursuit with the waypoint as carrot), slowing in sharp turns. At a corner the
next waypoint is about 90 degrees off and at a U-turn 180 degrees: both are turned on the
spot. :meth:`OffLanePilot.start_pose` starts on the first waypoint at a random heading.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from envs.coverage import street_mask
from envs.driving import bearing, pursuit_turn_rate
from localization._validation import check_real

__all__ = ["OffLanePilot", "off_lane_waypoints"]


def _graph(city: Any) -> tuple[NDArray[np.float64], dict[int, list[int]]]:
    nodes, edges = city.street_graph()
    neighbours: dict[int, list[int]] = {i: [] for i in range(len(nodes))}
    for i, j in edges:
        neighbours[i].append(j)
        neighbours[j].append(i)
    return np.asarray(nodes, dtype=np.float64), neighbours


def _on_street(city: Any, point: NDArray[np.float64], anchor: NDArray[np.float64],
               margin: float) -> NDArray[np.float64]:
    """``point`` if it is on the street ``margin`` clear of buildings, else moved towards the
    (free) ``anchor`` on the centreline until it is."""
    for shrink in (1.0, 0.75, 0.5, 0.25, 0.0):
        p = anchor + shrink * (point - anchor)
        if street_mask(city, p[None], margin)[0]:
            return p
    return anchor


def off_lane_waypoints(city: Any, length: float, rng: np.random.Generator,
                       weave: float = 0.6, spacing: float = 1.5, u_turn: float = 0.2,
                       margin: float = 0.32) -> NDArray[np.float64]:
    """Waypoints (p, 2) of a random off-lane drive at least ``length`` metres long (see the
    module docstring).

    Parameters
    ----------
    city : envs.scene.City
    length : float
        Least length (m) of the polyline.
    rng : numpy.random.Generator
    weave : float
        Largest sideways offset (m) of the weaving waypoints from the centreline.
    spacing : float
        Distance (m) along the street between weaving waypoints.
    u_turn : float
        Probability of turning back on a street (and, separately, at an intersection).
    margin : float
        Clearance (m) of every waypoint to buildings.
    """
    length = check_real(length, "length", low=0.0, low_open=True)
    weave = check_real(weave, "weave", low=0.0)
    spacing = check_real(spacing, "spacing", low=0.0, low_open=True)
    u_turn = check_real(u_turn, "u_turn", low=0.0, high=1.0)
    margin = check_real(margin, "margin", low=0.0)
    nodes, neighbours = _graph(city)
    hw = 0.5 * city.street_width

    def crossing(i: int) -> NDArray[np.float64]:
        jitter = rng.uniform(-1.0, 1.0, 2) * max(hw - margin, 0.0)
        return _on_street(city, nodes[i] + jitter, nodes[i], margin)

    prev, node = -1, int(rng.integers(len(nodes)))
    points, total, side = [crossing(node)], 0.0, float(rng.choice([-1.0, 1.0]))
    while total < length:
        options = [j for j in neighbours[node] if j != prev] or neighbours[node]
        nxt = prev if prev >= 0 and rng.uniform() < u_turn else \
            options[int(rng.integers(len(options)))]
        a, b = nodes[node], nodes[nxt]
        street = float(np.hypot(*(b - a)))
        d = (b - a) / street
        normal = np.array([-d[1], d[0]])
        ticks = np.arange(hw + 0.5 * spacing, street - hw, spacing)
        back = len(ticks) > 1 and rng.uniform() < u_turn
        if back:  # part way along, then turn back: a U-turn in the street
            ticks = ticks[: int(rng.integers(1, len(ticks)))]
        for t in ticks:
            side = -side
            offset = side * weave * rng.uniform(0.5, 1.0)
            points.append(_on_street(city, a + t * d + offset * normal, a + t * d, margin))
        if back:
            for t in ticks[::-1][1:]:
                side = -side
                offset = side * weave * rng.uniform(0.5, 1.0)
                points.append(_on_street(city, a + t * d + offset * normal, a + t * d, margin))
            prev, nxt = nxt, node  # arriving back where it came from
        else:
            prev = node
        points.append(crossing(nxt))
        node = nxt
        total = float(np.sum(np.hypot(*np.diff(np.array(points), axis=0).T)))
    return np.array(points)


class OffLanePilot:
    """Drive through waypoints, turning on the spot where they lie far off the heading.

    Parameters
    ----------
    waypoints : (p, 2) float
        Points to visit in order; the pilot stops after the last one.
    speed : float
        Forward speed command (m/s).
    w_max : float
        Bound on the turn rate command (rad/s).
    reach : float
        A waypoint is reached within this distance (m).
    turn_in_place : float
        Bearing (rad) beyond which the robot stops and turns on the spot.
    """

    def __init__(self, waypoints: NDArray[np.float64], speed: float = 0.6, w_max: float = 1.0,
                 reach: float = 0.25, turn_in_place: float = 0.8) -> None:
        wp = np.asarray(waypoints, dtype=np.float64)
        if wp.ndim != 2 or wp.shape[1] != 2 or len(wp) < 2 or not np.all(np.isfinite(wp)):
            raise ValueError(f"waypoints must be finite with shape (p >= 2, 2), got {wp.shape}")
        self.waypoints = wp
        self.speed = check_real(speed, "speed", low=0.0, low_open=True)
        self.w_max = check_real(w_max, "w_max", low=0.0, low_open=True)
        self.reach = check_real(reach, "reach", low=0.0, low_open=True)
        self.turn_in_place = check_real(turn_in_place, "turn_in_place", low=0.0, low_open=True)
        self.index, self.spinning = 1, False

    def start_pose(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """The first waypoint at a random heading, (3,); the pilot heads for the second."""
        self.index, self.spinning = 1, False
        return np.array([*self.waypoints[0], rng.uniform(-np.pi, np.pi)])

    @property
    def done(self) -> bool:
        """Whether the last waypoint has been reached."""
        return self.index >= len(self.waypoints)

    def __call__(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """The control U = [v, w] for the (estimated) pose [x, y, yaw]."""
        while not self.done and np.hypot(*(self.waypoints[self.index] - pose[:2])) < self.reach:
            self.index += 1
        if self.done:
            return np.zeros(2)
        target = self.waypoints[self.index]
        alpha = bearing(pose, target)
        limit = 0.2 * self.turn_in_place if self.spinning else self.turn_in_place
        self.spinning = abs(alpha) > limit
        if self.spinning:
            return np.array([0.0, float(np.clip(2.0 * alpha, -self.w_max, self.w_max))])
        distance = float(np.hypot(*(target - pose[:2])))
        v = self.speed * max(0.3, float(np.cos(alpha)))
        return np.array([v, pursuit_turn_rate(alpha, v, max(distance, self.reach), self.w_max)])
