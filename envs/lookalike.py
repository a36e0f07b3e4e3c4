"""A look-alike city: every block is the same block, except for a few landmark buildings.

``gymnasium.make("AppearanceNav-v0", city_layout="lookalike")`` builds it. One block of
buildings is drawn from the seed (footprints, heights, colours, window textures) and copied
into every block of the street grid, so the city is periodic with period
:attr:`LookalikeCity.period` (block side + street width) along x and y: a pose and the same
pose moved by ``(i * period, j * period)`` are *twins* and see the same image. A few
*landmark* buildings break the symmetry: in ``n_landmarks`` blocks one building keeps its
footprint and height but is painted a saturated colour, so it is seen only from the streets
next to it and only there can an image tell twins apart.

Everything else that could tell twins apart is made periodic too: the ground is one
uniform tint with streets continued to the horizon (no per-block tint, no grass edge), the
horizon walls are one flat sky colour (no skyline, no per-side colour), and the blocks
repeat, visual only and out of reach, for two rings beyond the city's boundary walls. The
remaining differences are far away (the ends of those rings) and cover a few pixels near
the horizon.

The twins of a pose are :meth:`LookalikeCity.twins`; the env reports the true pose's twins
in ``info["twins"]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from envs.city_model import _fmt
from envs.scene import _LANDMARK_COLOURS, Building, City, _block_buildings, _street_centers
from localization._validation import check_array, check_int, check_real, check_seed

__all__ = ["SKY_RGB", "LookalikeCity", "generate_lookalike_city"]

SKY_RGB = (0.78, 0.84, 0.9)  # every horizon wall, top to bottom
_TINT = (0.68, 0.68, 0.66)  # pavement, every block
DECOR_RINGS = 2  # rings of visual-only blocks beyond the boundary walls


@dataclass
class LookalikeCity(City):
    """A :class:`~envs.scene.City` of identical blocks (see the module docstring).

    Attributes
    ----------
    period : float — block side + street width (m): twins differ by integer multiples of it
        along x and y.
    decor : list of Building — the visual-only blocks beyond the boundary walls.
    landmark_blocks : (n_landmarks, 2) int — (column, row) of the blocks holding a landmark.
    """

    period: float = 0.0
    decor: list[Building] = field(default_factory=list)
    landmark_blocks: NDArray[np.int64] = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    # ------------------------------------------------------------------ twins
    def twin_shifts(self, xy: ArrayLike) -> NDArray[np.float64]:
        """Translations ``(i * period, j * period) != 0`` keeping the point ``xy`` in the city.

        Parameters
        ----------
        xy : (2,) float — a position [x, y] (a pose's first two entries).

        Returns
        -------
        (m, 2) float — the shifts, nearest first.
        """
        p = check_array(np.asarray(xy, dtype=np.float64)[:2], "xy", shape=(2,), what="[x, y]")
        k = len(self.street_centers)
        steps = np.arange(-k, k + 1)
        ii, jj = np.meshgrid(steps, steps, indexing="ij")
        shifts = self.period * np.column_stack([ii.ravel(), jj.ravel()])
        shifts = shifts[np.any(shifts != 0, axis=1)]
        inside = np.all(np.abs(p + shifts) <= self.half, axis=1)
        shifts = shifts[inside]
        return shifts[np.argsort(np.hypot(*shifts.T), kind="stable")]

    def twins(self, pose: ArrayLike) -> NDArray[np.float64]:
        """The twin poses of ``pose`` [x, y, yaw]: same heading, shifted by :meth:`twin_shifts`.

        Returns
        -------
        (m, 3) float — nearest first; a twin may fall in a landmark's view, where the images
        differ.
        """
        p = check_array(pose, "pose", shape=(3,), what="[x, y, yaw]")
        shifts = self.twin_shifts(p[:2])
        return np.column_stack([p[:2] + shifts, np.full(len(shifts), p[2])])

    # ------------------------------------------------------------------ appearance
    def ground_image(self, pixels: int = 1024, extent: float | None = None) -> NDArray[np.uint8]:
        """Paint the ground, periodic with :attr:`period` over the whole floor.

        Same markings as :meth:`City.ground_image` (asphalt, dashed centre lines, zebra
        crossings), with one pavement tint and no grass; the dash and zebra periods are
        rounded so that :attr:`period` holds a whole number of them.
        """
        e = self.floor_half() if extent is None else extent
        ticks = -e + (np.arange(pixels) + 0.5) * (2 * e / pixels)
        x, y = ticks[None, :], ticks[::-1, None]
        c0, T, hw = float(self.street_centers[0]), self.period, 0.5 * self.street_width
        ux, uy = np.mod(x - c0, T), np.mod(y - c0, T)
        dx, dy = np.minimum(ux, T - ux), np.minimum(uy, T - uy)
        dash, zebra = T / max(1, round(T)), T / max(1, round(4 * T))
        cross = (dx <= hw) & (dy <= hw)
        dash_x, dash_y = np.mod(ux, dash) < 0.5 * dash, np.mod(uy, dash) < 0.5 * dash
        zebra_x, zebra_y = np.mod(ux, zebra) < 0.5 * zebra, np.mod(uy, zebra) < 0.5 * zebra
        img = np.empty((pixels, pixels, 3))
        img[:] = _TINT
        img[(dx <= hw) | (dy <= hw)] = (0.22, 0.22, 0.24)
        img[~cross & (((dx < 0.05) & dash_y) | ((dy < 0.05) & dash_x))] = (0.9, 0.88, 0.6)
        img[~cross & (((dx <= hw) & (dy <= hw + 0.6) & zebra_x)
                      | ((dy <= hw) & (dx <= hw + 0.6) & zebra_y))] = (0.92, 0.92, 0.92)
        return (img * 255).astype(np.uint8)

    def horizon_image(self, side: str, width: int = 512, height: int = 256) -> NDArray[np.uint8]:
        """One flat sky colour on every side (a gradient or a skyline would tell places apart)."""
        if side not in ("E", "N", "W", "S"):
            raise ValueError(f"unknown side {side!r}; choose one of ['E', 'N', 'W', 'S']")
        return np.full((height, width, 3), np.round(np.asarray(SKY_RGB) * 255), dtype=np.uint8)

    def _obstacles_xml(self) -> tuple[list[str], list[str]]:
        """The city's buildings and walls, plus the decor blocks (never collide, group 2)."""
        assets, geoms = super()._obstacles_xml()
        looks: dict[tuple, int] = {}  # one material per distinct look, shared by the copies
        for i, b in enumerate(self.decor):
            key = (b.rgb, b.window_rgb)
            if key not in looks:
                looks[key] = k = len(looks)
                assets.append(
                    f'<texture name="decortex{k}" type="2d" builtin="checker" width="32" '
                    f'height="32" rgb1="{_fmt(b.rgb)}" rgb2="{_fmt(b.window_rgb)}"/>'
                )
                assets.append(f'<material name="decormat{k}" texture="decortex{k}" '
                              'texrepeat="2 2.5" texuniform="true"/>')
            geoms.append(
                f'<geom name="decor{i}" type="box" pos="{_fmt(b.center)}" size="{_fmt(b.half_size)}" '
                f'material="decormat{looks[key]}" contype="0" conaffinity="0" group="2"/>'
            )
        return assets, geoms


def _shifted(b: Building, dx: float, dy: float) -> Building:
    return replace(b, center=(b.center[0] + dx, b.center[1] + dy, b.center[2]))


def generate_lookalike_city(
    seed: int,
    city_size: float = 20.0,
    block_size: float = 4.0,
    street_width: float = 2.0,
    max_height: float = 4.0,
    n_landmarks: int = 2,
) -> LookalikeCity:
    """Generate the look-alike city named by ``seed`` (see the module docstring).

    Parameters
    ----------
    seed : int — draws the one block, the landmark blocks, buildings and colours.
    city_size, block_size, street_width, max_height : float — as :func:`envs.scene.generate_city`.
    n_landmarks : int — blocks whose one building is painted a landmark colour; at most the
        number of blocks minus one (some blocks must stay twins).

    Raises
    ------
    ValueError
        If the layout has a single block (no twins), or ``n_landmarks`` leaves no two
        identical blocks.
    """
    seed = check_seed(seed, "seed")
    for name, v in (("city_size", city_size), ("block_size", block_size),
                    ("street_width", street_width), ("max_height", max_height)):
        check_real(v, name, low=0.0, low_open=True)
    check_int(n_landmarks, "n_landmarks", low=0)
    centers = _street_centers(city_size, block_size, street_width)
    n_side = len(centers) - 1
    if n_side < 2:
        raise ValueError(
            f"city_layout='lookalike' needs at least 2 blocks along a side to have twins; "
            f"city_size={city_size}, block_size={block_size}, street_width={street_width} give 1"
        )
    if n_landmarks > n_side * n_side - 2:
        raise ValueError(f"n_landmarks={n_landmarks} leaves no two identical blocks among "
                         f"the {n_side * n_side} blocks; use at most {n_side * n_side - 2}")
    rng = np.random.default_rng([seed, 12])
    period = float(centers[1] - centers[0])
    hw = 0.5 * street_width
    lo, hi = np.array([centers[0] + hw] * 2), np.array([centers[1] - hw] * 2)
    template = _block_buildings(rng, lo, hi, max_height)
    while not template:  # an all-empty block would make a city of bare streets
        template = _block_buildings(rng, lo, hi, max_height)
    blocks = rng.permutation(n_side * n_side)[:n_landmarks]
    marked = {int(b): int(rng.integers(len(template))) for b in blocks}
    buildings: list[Building] = []
    for row, col in ((r, c) for r in range(n_side) for c in range(n_side)):
        for k, b in enumerate(template):
            moved = _shifted(b, col * period, row * period)
            if marked.get(row * n_side + col) == k:
                rgb = _LANDMARK_COLOURS[sorted(marked).index(row * n_side + col) % len(_LANDMARK_COLOURS)]
                moved = replace(moved, rgb=tuple(rgb), window_rgb=tuple(rgb * 0.4), landmark=True)
            buildings.append(moved)
    ring = range(-DECOR_RINGS, n_side + DECOR_RINGS)
    decor = [_shifted(b, c * period, r * period) for r in ring for c in ring
             if not (0 <= r < n_side and 0 <= c < n_side) for b in template]
    landmark_blocks = np.array([[b % n_side, b // n_side] for b in sorted(marked)], dtype=np.int64)
    return LookalikeCity(size=float(city_size), street_width=float(street_width),
                         street_centers=centers, buildings=buildings, seed=int(seed), skyline=[],
                         period=period, decor=decor,
                         landmark_blocks=landmark_blocks.reshape(-1, 2))

