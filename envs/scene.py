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
(:meth:`City.route`) and :meth:`City.to_mjcf` for the MuJoCo world.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from localization._validation import check_int, check_real, check_seed

__all__ = ["Building", "City", "generate_city"]

_LANDMARK_COLOURS = np.array(
    [[0.9, 0.1, 0.1], [0.1, 0.3, 0.95], [0.95, 0.85, 0.1], [0.1, 0.8, 0.2], [0.8, 0.1, 0.8]]
)
GROUND_PIXELS = 1024  # floor texture side
HORIZON_PIXELS = (512, 256)  # horizon wall texture (width, height)
HORIZON_HEIGHT = 40.0  # m
# horizon walls: distinct colours per side so heading is visible from far away
_HORIZON = {"E": (0.85, 0.55, 0.35), "N": (0.45, 0.6, 0.85), "W": (0.55, 0.8, 0.55), "S": (0.8, 0.75, 0.5)}


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
class City:
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

    # ------------------------------------------------------------------ MJCF
    def to_mjcf(self, robot_xml: str = "", robot_assets: str = "", actuators: str = "", sensors: str = "",
                timestep: float = 0.01) -> str:
        """Return a MuJoCo MJCF document for the city (plus optional robot parts).

        The collidable buildings and the invisible boundary walls are geoms of the static
        body ``"city"`` (so a contact sensor can watch them); floor and horizon walls are
        visual-only world geoms whose textures are placeholders until :meth:`paint_textures`
        is applied to the compiled model.

        Parameters
        ----------
        robot_xml : str — body XML inserted into ``<worldbody>``.
        robot_assets : str — XML inserted into ``<asset>``.
        actuators : str — XML inserted into ``<actuator>``.
        sensors : str — XML inserted into ``<sensor>``.
        timestep : float — physics step (s); with the soft contacts (solref 0.03 s) 10 ms is smooth.
        """
        far = self.floor_half() - 2.0  # horizon walls
        extent = 2.0 * far  # znear/zfar are in units of the extent
        assets, scenery = self._scenery_xml(far)
        obstacle_assets, obstacles = self._obstacles_xml()
        join = "\n      ".join
        return f"""<mujoco model="appearance_nav_city_{self.seed}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{timestep}" integrator="implicitfast"/>
  <statistic extent="{extent:.3f}" center="0 0 0"/>
  <default><geom solref="0.03 1"/></default>
  <visual>
    <quality offsamples="0" shadowsize="0"/>
    <global offwidth="640" offheight="480"/>
    <map znear="{0.02 / extent:.6f}" zfar="{3.0 * far / extent:.6f}"/>
    <headlight ambient="0.45 0.45 0.45" diffuse="0.35 0.35 0.35" specular="0 0 0"/>
  </visual>
  <asset>
      {join(assets + obstacle_assets)}
      {robot_assets}
  </asset>
  <worldbody>
    <light name="sun" directional="true" castshadow="false" pos="0 0 10" dir="0.3 0.4 -1" diffuse="0.5 0.5 0.5"/>
      {join(scenery)}
    <body name="city">
      {join(obstacles)}
    </body>
    {robot_xml}
  </worldbody>
  <actuator>
    {actuators}
  </actuator>
  <sensor>
    {sensors}
  </sensor>
</mujoco>
"""

    def floor_half(self) -> float:
        """Half side of the floor plane, whose texture :meth:`ground_image` paints."""
        return self.half + 14.0

    def ground_image(self, pixels: int = 1024, extent: float | None = None) -> NDArray[np.uint8]:
        """Paint the ground seen from above, (pixels, pixels, 3) uint8, row 0 = north.

        Covers ``[-extent, extent]^2`` (default the floor plane): asphalt streets with
        dashed centre lines and zebra crossings at the intersections, pavement blocks
        with a per-block tint, and grass outside the city.
        """
        e = self.floor_half() if extent is None else extent
        ticks = -e + (np.arange(pixels) + 0.5) * (2 * e / pixels)
        # everything is separable: 1-D masks along x (columns) and y (rows), broadcast
        x, y = ticks[None, :], ticks[::-1, None]
        hw, c = 0.5 * self.street_width, self.street_centers
        dx = np.abs(x[..., None] - c).min(-1)  # distance to the nearest N-S street centre line
        dy = np.abs(y[..., None] - c).min(-1)
        inside = (np.abs(x) <= self.half) & (np.abs(y) <= self.half)
        cross = (dx <= hw) & (dy <= hw)
        dash_x, dash_y = np.mod(x, 1.0) < 0.5, np.mod(y, 1.0) < 0.5
        zebra_x, zebra_y = np.mod(4 * x, 1.0) < 0.5, np.mod(4 * y, 1.0) < 0.5
        tint = np.random.default_rng([self.seed, 1]).uniform(0.6, 0.78, (len(c) + 1, len(c) + 1, 3))
        img = tint[np.searchsorted(c, y[:, 0])][:, np.searchsorted(c, x[0])]  # pavement, one tint per block
        img[~inside] = (0.33, 0.40, 0.28)  # grass
        img[inside & ((dx <= hw) | (dy <= hw))] = (0.22, 0.22, 0.24)  # asphalt
        img[inside & ~cross & (((dx < 0.05) & dash_y) | ((dy < 0.05) & dash_x))] = (0.9, 0.88, 0.6)
        img[inside & ~cross & (((dx <= hw) & (dy <= hw + 0.6) & zebra_x)
                               | ((dy <= hw) & (dx <= hw + 0.6) & zebra_y))] = (0.92, 0.92, 0.92)
        return (img * 255).astype(np.uint8)

    def horizon_image(self, side: str, width: int = 512, height: int = 256) -> NDArray[np.uint8]:
        """Paint the horizon wall on ``side`` ("E", "N", "W", "S") as seen from inside the city.

        Returns (height, width, 3) uint8; row 0 is the wall top (``HORIZON_HEIGHT`` m), column 0
        the left end as seen looking out. A sky gradient to the side's colour, and the
        :attr:`skyline` towers of that side drawn as seen from the city centre (scaled by
        wall distance / tower distance), far ones first, with lit window dots.
        """
        far = self.floor_half() - 2.0
        axis, sign = {"E": (0, 1), "N": (1, 1), "W": (0, -1), "S": (1, -1)}[side]
        left = {"E": 1, "N": -1, "W": -1, "S": 1}[side]  # along-wall coordinate increasing to the left
        z = HORIZON_HEIGHT * (1.0 - (np.arange(height) + 0.5) / height)[:, None, None]
        t = np.clip(z / 12.0, 0.0, 1.0)
        img = (1 - t) * np.asarray(_HORIZON[side]) + t * np.array([0.93, 0.96, 1.0]) + np.zeros((1, width, 3))
        col = (far - left * (-far + (np.arange(width) + 0.5) * 2 * far / width))[None, :]  # left-to-right
        along = far - col  # along-wall coordinate of each column, in the "left" orientation
        mine = [b for b in self.skyline if sign * b.center[axis] > self.half]
        for b in sorted(mine, key=lambda b: -abs(b.center[axis])):
            k = far / abs(b.center[axis])
            a, w, hz = left * b.center[1 - axis] * k, b.half_size[1 - axis] * k, 2 * b.half_size[2] * k
            body = (np.abs(along - a) <= w) & (z[..., 0] <= hz)
            img[body] = b.rgb
            lit = body & (np.mod(z[..., 0], 1.2) < 0.5) & (np.mod(along - a, 0.9) < 0.4)
            img[lit] = np.clip(np.asarray(b.window_rgb) + 0.35, 0, 1)
        return (img * 255).astype(np.uint8)

    def paint_textures(self, model: mujoco.MjModel) -> None:  # noqa: F821
        """Write :meth:`ground_image` and :meth:`horizon_image` into the compiled model's textures.

        Call before any renderer is created for the model (textures are uploaded then).
        """
        import mujoco

        def paint(name: str, image: NDArray[np.uint8]) -> None:
            tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXTURE, name)
            a, h, w, c = model.tex_adr[tid], model.tex_height[tid], model.tex_width[tid], model.tex_nchannel[tid]
            model.tex_data[a : a + h * w * c] = image[:h, :w, :c].reshape(-1)

        paint("ground", self.ground_image(GROUND_PIXELS))
        for side in "ENWS":  # MuJoCo maps the inner faces of the W and N walls mirrored
            image = self.horizon_image(side, *HORIZON_PIXELS)
            paint(f"sky{side}", image[:, ::-1] if side in "WN" else image)

    def _obstacles_xml(self) -> tuple[list[str], list[str]]:
        """Assets and geoms of the collidable buildings and invisible boundary walls."""
        h, assets, geoms = self.half, [], []
        for i, b in enumerate(self.buildings):
            assets.append(
                f'<texture name="tex{i}" type="2d" builtin="checker" width="32" height="32" '
                f'rgb1="{_fmt(b.rgb)}" rgb2="{_fmt(b.window_rgb)}"/>'
            )
            assets.append(f'<material name="mat{i}" texture="tex{i}" texrepeat="2 2.5" texuniform="true"/>')
            geoms.append(
                f'<geom name="building{i}" type="box" pos="{_fmt(b.center)}" size="{_fmt(b.half_size)}" '
                f'material="mat{i}" contype="2" conaffinity="2" group="2"/>'
            )
        for name, (x, y, hx, hy) in {  # invisible walls keep the robot in the city
            "E": (h + 0.25, 0, 0.25, h + 0.5), "W": (-h - 0.25, 0, 0.25, h + 0.5),
            "N": (0, h + 0.25, h + 0.5, 0.25), "S": (0, -h - 0.25, h + 0.5, 0.25),
        }.items():
            geoms.append(
                f'<geom name="wall{name}" type="box" pos="{x} {y} 0.5" size="{hx} {hy} 0.5" '
                'rgba="1 1 1 0" contype="2" conaffinity="2" group="3"/>'
            )
        return assets, geoms

    def _scenery_xml(self, far: float) -> tuple[list[str], list[str]]:
        """Assets and visual-only geoms: floor and horizon walls (painted by :meth:`paint_textures`)."""
        f = far + 2.0
        assets = [
            (f'<texture name="ground" type="2d" builtin="flat" width="{GROUND_PIXELS}" '
             f'height="{GROUND_PIXELS}" rgb1="0.3 0.3 0.3"/>'),
            '<material name="ground" texture="ground" texrepeat="1 1"/>',
        ]
        # a plane's third size is its rendering grid spacing: one big cell draws fastest
        geoms = [(f'<geom name="floor" type="plane" size="{f:.3f} {f:.3f} {f:.3f}" material="ground" '
                  'contype="1" conaffinity="1" group="0"/>')]
        zc = 0.5 * HORIZON_HEIGHT
        for name, (x, y, hx, hy) in {
            "E": (far, 0, 0.5, far), "W": (-far, 0, 0.5, far), "N": (0, far, far, 0.5), "S": (0, -far, far, 0.5)
        }.items():
            assets.append(
                f'<texture name="sky{name}" type="2d" builtin="flat" width="{HORIZON_PIXELS[0]}" '
                f'height="{HORIZON_PIXELS[1]}" rgb1="{_fmt(_HORIZON[name])}"/>'
            )
            assets.append(f'<material name="sky{name}" texture="sky{name}" texrepeat="1 1"/>')
            geoms.append(
                f'<geom name="horizon{name}" type="box" pos="{x} {y} {zc}" size="{hx} {hy} {zc}" '
                f'material="sky{name}" contype="0" conaffinity="0" group="2"/>'
            )
        return assets, geoms


def _fmt(values: tuple[float, ...]) -> str:
    return " ".join(f"{v:.3f}" for v in values)


def _street_centers(size: float, block_size: float, street_width: float) -> NDArray[np.float64]:
    n_blocks = int(np.floor((size - street_width) / (block_size + street_width) + 1e-9))
    if n_blocks < 1:
        raise ValueError(
            f"city_size={size} too small for one block of {block_size} m between streets of {street_width} m"
        )
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
    skyline = _skyline(rng, 0.5 * city_size)
    return City(size=float(city_size), street_width=float(street_width), street_centers=centers,
                buildings=buildings, seed=int(seed), skyline=skyline)


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
