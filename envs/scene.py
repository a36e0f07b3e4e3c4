"""A procedurally generated city: street grid, box buildings, street graph, MJCF.

The city is a square ``[-city_size/2, city_size/2]^2`` (metres) cut by a regular
grid of streets of width ``street_width``; the streets along the border form a
ring, so every block is surrounded by streets. Each block holds one to four
box buildings of random footprint, height, colour and window texture, and a
few blocks hold a tall, saturated "landmark" tower. Everything random comes
from ``np.random.default_rng(seed)``, so a seed names a city.

The :class:`City` is plain data (buildings as axis-aligned boxes) with queries
(:meth:`City.is_free`, :meth:`City.random_free_pose`), the street graph agents
plan over (:meth:`City.street_graph`), a closed driving loop
(:meth:`City.route`); :meth:`City.to_mjcf` builds the MuJoCo world
(:mod:`envs.city_model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from envs.city_model import CityModelMixin
from localization._validation import check_int, check_real, check_seed

__all__ = ["Building", "City", "check_city_layout", "generate_city"]

_LANDMARK_COLOURS = np.array(
    [[0.9, 0.1, 0.1], [0.1, 0.3, 0.95], [0.95, 0.85, 0.1], [0.1, 0.8, 0.2], [0.8, 0.1, 0.8]]
)


@dataclass(frozen=True)
class Building:
    """An axis-aligned box building.

    Attributes
    ----------
    center : (3,) float — box centre (x, y, z) in metres (z = half height).
    half_size : (3,) float — half extents (hx, hy, hz).
    rgb : (3,) float — wall colour in [0, 1].
    window_rgb : (3,) float — colour of the window checker texture.
    landmark : bool — whether this is a tall, saturated landmark tower.
    """

    center: tuple[float, float, float]
    half_size: tuple[float, float, float]
    rgb: tuple[float, float, float]
    window_rgb: tuple[float, float, float]
    landmark: bool = False


@dataclass
class City(CityModelMixin):
    """A street-grid city (see the module docstring).

    Attributes
    ----------
    size : float — side of the square city in metres.
    street_width : float — street width in metres.
    street_centers : (k,) float — coordinates of the street centrelines (same on x and y).
    buildings : list of Building — the collidable buildings inside the city.
    seed : int — the generating seed.
    skyline : list of Building — towers outside the city, painted onto the horizon walls
        (as seen from the city centre) so views out of the city differ from place to place
        and direction to direction at no extra draw calls.
    """

    size: float
    street_width: float
    street_centers: NDArray[np.float64]
    buildings: list[Building] = field(default_factory=list)
    seed: int = 0
    skyline: list[Building] = field(default_factory=list)

    # ------------------------------------------------------------------ geometry
    @property
    def half(self) -> float:
        """Half the city side: the city is ``[-half, half]^2``."""
        return 0.5 * self.size

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high) of both coordinates."""
        return -self.half, self.half

    def street_area(self) -> float:
        """Area (m^2) of the streets: the city's square less the blocks between the streets
        (256 m^2 in the default 20 m city, 2000 m^2 in a 60 m one)."""
        c = self.street_centers
        block = np.diff(c) - self.street_width
        return float(self.size ** 2 - np.sum(block[:, None] * block[None, :]))

    def footprints(self) -> NDArray[np.float64]:
        """Return building footprints as (n, 4) rows ``[xmin, ymin, xmax, ymax]``."""
        if not self.buildings:
            return np.zeros((0, 4))
        c = np.array([b.center[:2] for b in self.buildings])
        h = np.array([b.half_size[:2] for b in self.buildings])
        return np.hstack([c - h, c + h])

    def is_free(self, x: float, y: float, margin: float = 0.0) -> bool:
        """Return whether a disc of radius ``margin`` at (x, y) is inside the city and off buildings."""
        return bool(self.free_mask(np.array([[x, y]], dtype=np.float64), margin)[0])

    def free_mask(self, points: NDArray[np.float64], margin: float = 0.0) -> NDArray[np.bool_]:
        """Vectorised :meth:`is_free` for (n, 2) points, returns (n,) bool."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        ok = np.all(np.isfinite(p), axis=1) & np.all(np.abs(p) <= self.half - margin, axis=1)
        fp = self._fp
        x, y = p[:, :1], p[:, 1:]
        hit = (fp[:, 0] - margin < x) & (x < fp[:, 2] + margin) & (fp[:, 1] - margin < y) & (y < fp[:, 3] + margin)
        return ok & ~hit.any(axis=1)

    def clearance(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance (m) from each of the (n, 2) points to the nearest building or the city's
        edge, (n,): negative inside a building or outside the city, NaN for a non-finite
        point. ``clearance(p) >= margin`` wherever ``free_mask(p, margin)`` (which grows the
        buildings by squares, not discs: beside a corner it is stricter)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        edge = self.half - np.max(np.abs(p), axis=1)
        fp = self._fp
        if len(fp) == 0:
            return edge
        dx = np.maximum(fp[None, :, 0] - p[:, :1], p[:, :1] - fp[None, :, 2])
        dy = np.maximum(fp[None, :, 1] - p[:, 1:], p[:, 1:] - fp[None, :, 3])
        outside = np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0))
        box = np.where((dx <= 0) & (dy <= 0), np.maximum(dx, dy), outside)
        return np.minimum(edge, box.min(axis=1))

    @property
    def _fp(self) -> NDArray[np.float64]:
        cached = getattr(self, "_fp_cache", None)
        if cached is None or len(cached) != len(self.buildings):
            cached = self.footprints()
            self._fp_cache = cached
        return cached

    def random_free_pose(self, rng: np.random.Generator, margin: float = 0.3) -> NDArray[np.float64]:
        """Draw a uniform pose ``[x, y, yaw]`` on the streets (``margin`` from buildings), shape (3,)."""
        for _ in range(10_000):
            x, y = rng.uniform(-self.half + margin, self.half - margin, size=2)
            if self.is_free(x, y, margin):
                return np.array([x, y, rng.uniform(-np.pi, np.pi)])
        raise RuntimeError("no free pose found; streets too narrow for the margin")

    def random_street_point(self, rng: np.random.Generator) -> NDArray[np.float64]:
        """Draw a point on a street centreline (a random edge of the street graph), shape (2,)."""
        nodes, edges = self.street_graph()
        i, j = edges[rng.integers(len(edges))]
        t = rng.uniform()
        return (1.0 - t) * nodes[i] + t * nodes[j]

    # ------------------------------------------------------------------ graph
    def street_graph(self) -> tuple[NDArray[np.float64], list[tuple[int, int]]]:
        """Return the street graph: intersections and the street segments between them.

        Returns
        -------
        nodes : (k*k, 2) float — intersection positions; node ``i * k + j`` is at
            ``(street_centers[j], street_centers[i])`` (row i = y, column j = x).
        edges : list of (a, b) int pairs, a < b — straight street segments joining
            neighbouring intersections.
        """
        c = self.street_centers
        k = len(c)
        xx, yy = np.meshgrid(c, c)
        nodes = np.stack([xx.ravel(), yy.ravel()], axis=1)
        edges = []
        for i in range(k):
            for j in range(k):
                a = i * k + j
                if j + 1 < k:
                    edges.append((a, a + 1))
                if i + 1 < k:
                    edges.append((a, a + k))
        return nodes, edges

    def route(self) -> NDArray[np.float64]:
        """Return a closed driving loop through the streets, (p, 2) intersection waypoints.

        The loop visits every intersection once (a Hamiltonian cycle of the grid
        graph: up the first column, then snaking through the other columns) when
        the number of streets is even, else it is the outer ring. The last
        waypoint connects back to the first; consecutive waypoints are joined by
        a street segment.
        """
        nodes, _ = self.street_graph()
        k = len(self.street_centers)
        if k % 2 == 0:
            order = [(i, 0) for i in range(k - 1, -1, -1)]
            for i in range(k):
                cols = range(1, k) if i % 2 == 0 else range(k - 1, 0, -1)
                order += [(i, j) for j in cols]
        else:
            ring = [(0, j) for j in range(k)] + [(i, k - 1) for i in range(1, k)]
            ring += [(k - 1, j) for j in range(k - 2, -1, -1)] + [(i, 0) for i in range(k - 2, 0, -1)]
            order = ring
        return np.array([nodes[i * k + j] for i, j in order])


def check_city_layout(city_size: float, block_size: float = 4.0, street_width: float = 2.0) -> int:
    """The number of blocks along a side of the city these sizes (m) give.

    Raises
    ------
    TypeError, ValueError
        If a size is not a positive finite number, or the city is too small for one block
        between two streets.
    """
    for name, v in (("city_size", city_size), ("block_size", block_size),
                    ("street_width", street_width)):
        check_real(v, name, low=0.0, low_open=True)
    n_blocks = int(np.floor((city_size - street_width) / (block_size + street_width) + 1e-9))
    if n_blocks < 1:
        raise ValueError(f"city_size={city_size} too small for one block of {block_size} m "
                         f"between streets of {street_width} m")
    return n_blocks


def _street_centers(size: float, block_size: float, street_width: float) -> NDArray[np.float64]:
    n_blocks = check_city_layout(size, block_size, street_width)
    block = (size - street_width * (n_blocks + 1)) / n_blocks  # stretch blocks to fill the city
    first = -0.5 * size + 0.5 * street_width
    return first + np.arange(n_blocks + 1) * (block + street_width)


def _block_buildings(
    rng: np.random.Generator, lo: NDArray[np.float64], hi: NDArray[np.float64], max_height: float
) -> list[Building]:
    """Split the block [lo, hi] into 1-4 lots and put a building on each."""
    nx, ny = rng.integers(1, 3, size=2)
    xs = np.linspace(lo[0], hi[0], nx + 1)
    ys = np.linspace(lo[1], hi[1], ny + 1)
    if nx == 2:
        xs[1] += rng.uniform(-0.2, 0.2) * (hi[0] - lo[0])
    if ny == 2:
        ys[1] += rng.uniform(-0.2, 0.2) * (hi[1] - lo[1])
    out = []
    for i in range(nx):
        for j in range(ny):
            if rng.uniform() < 0.12:  # an empty lot (a small square)
                continue
            a, b = np.array([xs[i], ys[j]]), np.array([xs[i + 1], ys[j + 1]])
            inset = rng.uniform(0.05, 0.35, size=4)
            a2, b2 = a + inset[:2], b - inset[2:]
            if np.any(b2 - a2 < 0.4):
                a2, b2 = a + 0.05, b - 0.05
            height = rng.uniform(0.8, max_height)
            hsv_rgb = _random_colour(rng)
            win = np.clip(hsv_rgb * rng.uniform(0.2, 0.6) + rng.uniform(0.0, 0.15, 3), 0, 1)
            c, hs = 0.5 * (a2 + b2), 0.5 * (b2 - a2)
            out.append(Building((c[0], c[1], 0.5 * height), (hs[0], hs[1], 0.5 * height), tuple(hsv_rgb), tuple(win)))
    return out


def _random_colour(rng: np.random.Generator) -> NDArray[np.float64]:
    h, s, v = rng.uniform(), rng.uniform(0.15, 0.7), rng.uniform(0.45, 0.95)
    k = (np.array([5.0, 3.0, 1.0]) + h * 6.0) % 6.0
    return v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def generate_city(
    seed: int,
    city_size: float = 20.0,
    block_size: float = 4.0,
    street_width: float = 2.0,
    max_height: float = 4.0,
    n_landmarks: int = 3,
) -> City:
    """Generate the city named by ``seed``.

    Parameters
    ----------
    seed : int — scene seed for ``np.random.default_rng``.
    city_size : float — side of the square city (m).
    block_size : float — nominal block side (m); blocks are stretched so the grid fills the city.
    street_width : float — street width (m).
    max_height : float — tallest ordinary building (m); landmarks are taller.
    n_landmarks : int — number of tall, saturated towers (one per chosen block).
    """
    seed = check_seed(seed, "seed")
    for name, v in (("city_size", city_size), ("block_size", block_size), ("street_width", street_width),
                    ("max_height", max_height)):
        check_real(v, name, low=0.0, low_open=True)
    check_int(n_landmarks, "n_landmarks", low=0)
    rng = np.random.default_rng(seed)
    centers = _street_centers(city_size, block_size, street_width)
    half_w = 0.5 * street_width
    blocks = [
        (np.array([x0 + half_w, y0 + half_w]), np.array([x1 - half_w, y1 - half_w]))
        for y0, y1 in pairwise(centers)
        for x0, x1 in pairwise(centers)
    ]
    buildings: list[Building] = []
    for lo, hi in blocks:
        buildings += _block_buildings(rng, lo, hi, max_height)
    order = rng.permutation(len(blocks))[: min(n_landmarks, len(blocks))]
    for rank, bi in enumerate(order):
        lo, hi = blocks[bi]
        c = lo + rng.uniform(0.3, 0.7, size=2) * (hi - lo)
        r = min(0.5, 0.2 * float(np.min(hi - lo)))
        height = rng.uniform(1.6, 2.2) * max_height
        buildings = [b for b in buildings if not _overlaps(b, c, r)]
        rgb = _LANDMARK_COLOURS[rank % len(_LANDMARK_COLOURS)]
        buildings.append(Building((c[0], c[1], 0.5 * height), (r, r, 0.5 * height), tuple(rgb), tuple(rgb * 0.4), True))
    skyline = _skyline(rng, 0.5 * city_size, _skyline_per_side(city_size))
    return City(size=float(city_size), street_width=float(street_width), street_centers=centers,
                buildings=buildings, seed=int(seed), skyline=skyline)


def _skyline_per_side(city_size: float) -> int:
    """Towers per side of the skyline: 10 along the default 20 m city's 28 m of horizon side,
    as dense on a bigger city's (24 on a 60 m city), never fewer than 10."""
    return max(10, round(10 * (city_size + 8.0) / 28.0))


def _skyline(rng: np.random.Generator, half: float, per_side: int = 10) -> list[Building]:
    """Towers 2-9 m outside each side of the city, of random size and colour (painted on the horizon)."""
    out = []
    for side in range(4):
        along = np.sort(rng.uniform(-half - 4.0, half + 4.0, per_side))
        for a in along:
            d = half + rng.uniform(2.0, 9.0)
            w, depth, height = rng.uniform(1.0, 4.0), rng.uniform(0.8, 2.5), rng.uniform(2.0, 12.0)
            x, y, hx, hy = [(d, a, depth, w), (a, d, w, depth), (-d, a, depth, w), (a, -d, w, depth)][side]
            rgb = _random_colour(rng) * rng.uniform(0.6, 1.0)
            out.append(Building((x, y, 0.5 * height), (0.5 * hx, 0.5 * hy, 0.5 * height), tuple(rgb), tuple(rgb * 0.5)))
    return out


def _overlaps(b: Building, c: NDArray[np.float64], r: float) -> bool:
    return abs(b.center[0] - c[0]) < b.half_size[0] + r + 0.1 and abs(b.center[1] - c[1]) < b.half_size[1] + r + 0.1
