"""Coverage of the whole drivable street surface at every heading: training poses for a
localizer that must work anywhere a robot can be, not only on the driving lanes.

:func:`coverage_poses` draws n poses ``[x, y, yaw]``:

- **positions** uniform over the free street surface (:func:`street_mask`: the asphalt strips
  of the street grid, ``margin`` metres clear of buildings and of the city's border; or, with
  ``region="free"``, every free point, pavements and empty lots included), with the
  intersections weighted up: a point within ``corner_reach`` metres of an intersection square
  is ``1 + corner_weight`` times as likely. At a corner the view changes fastest with position
  (a side street opens up, a building edge sweeps across the image), and a robot turning
  there sweeps through every heading;
- **headings** stratified: the n headings fall one in each of n equal slices of
  ``[-pi, pi)`` (a random slice order, a uniform offset in each), so every heading range of
  width ``2 pi k / n`` holds k of them (within one), whatever the seed.

The density a camera needs: a perspective camera (75 degrees) sees a different picture every
few degrees of heading, so its poses must cover heading as densely as position, which the
stratified headings do for every n. An omnidirectional camera sees all around, and in
principle a heading change only rotates its image (the catadioptric ring is a map view,
forward at the top), so one render could give four training images by quarter turns. Not
here: rendered from a cube map, the ring image of a robot turned by 90 degrees about its
camera differs from the turned image by 17/255 per pixel on average (city 11, 64 x 64; a 5 cm
step changes it by 1.2/255): the buildings line up, the sky and horizon shading do not. So
every camera gets rendered poses.

Everything random comes from the generator passed in: the same seed gives the same poses.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from localization._validation import check_choice, check_int, check_real

__all__ = ["REGIONS", "corner_mask", "coverage_poses", "street_mask"]

REGIONS = ("streets", "free")
CORNER_WEIGHT = 1.0  # a corner zone is twice as likely (chosen on tuning city 13: docs/method.md §12)
CORNER_REACH = 1.0  # m beyond the intersection square
BATCH = 4096  # candidate positions per rejection round


def _check_points(points: object) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {p.shape}")
    return p


def street_mask(city: Any, points: NDArray[np.float64], margin: float = 0.32,
                region: str = "streets") -> NDArray[np.bool_]:
    """Which points (n, 2) lie on the street surface, ``margin`` metres clear of obstacles.

    Parameters
    ----------
    city : envs.scene.City
    points : (n, 2) float
    margin : float
        Clearance (m) to buildings and to the city's border (``city.free_mask``).
    region : {"streets", "free"}
        "streets": on the asphalt (within half a street width of a street centreline) as
        well; "free": any free point.

    Returns
    -------
    (n,) bool
    """
    p = _check_points(points)
    check_real(margin, "margin", low=0.0)
    check_choice(region, "region", REGIONS)
    free = city.free_mask(p, margin)
    if region == "free":
        return free
    c, hw = np.asarray(city.street_centers), 0.5 * city.street_width
    near = [np.min(np.abs(p[:, k, None] - c[None, :]), axis=1) <= hw for k in (0, 1)]
    return free & (near[0] | near[1])


def corner_mask(city: Any, points: NDArray[np.float64], reach: float = CORNER_REACH
                ) -> NDArray[np.bool_]:
    """Which points (n, 2) lie within ``reach`` metres (per axis) of an intersection square
    (the street width on a side, centred on a street-graph node); returns (n,) bool."""
    p = _check_points(points)
    reach = check_real(reach, "reach", low=0.0)
    c = np.asarray(city.street_centers)
    lim = 0.5 * city.street_width + reach
    return np.all(np.min(np.abs(p[:, :, None] - c[None, None, :]), axis=2) <= lim, axis=1)


def coverage_poses(city: Any, n: int, rng: np.random.Generator, margin: float = 0.32,
                   region: str = "streets", corner_weight: float = CORNER_WEIGHT,
                   corner_reach: float = CORNER_REACH) -> NDArray[np.float64]:
    """Draw n poses over the street surface at every heading (see the module docstring).

    Parameters
    ----------
    city : envs.scene.City
    n : int
    rng : numpy.random.Generator
    margin : float
        Clearance (m) to buildings and the border.
    region : {"streets", "free"}
        See :func:`street_mask`.
    corner_weight : float
        Extra weight of the corner zones (0: uniform over the surface).
    corner_reach : float
        How far (m) a corner zone reaches beyond its intersection square.

    Returns
    -------
    poses : (n, 3) float64 ``[x, y, yaw]``, yaw in [-pi, pi).

    Raises
    ------
    ValueError
        For a bad argument.
    RuntimeError
        If the street surface is (almost) empty at this margin.
    """
    n = check_int(n, "n", low=1)
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    margin = check_real(margin, "margin", low=0.0)
    check_choice(region, "region", REGIONS)
    corner_weight = check_real(corner_weight, "corner_weight", low=0.0)
    corner_reach = check_real(corner_reach, "corner_reach", low=0.0)
    lim = city.half - margin
    if lim <= 0:
        raise ValueError(f"margin={margin} leaves no room in a city of size {city.size}")
    top = 1.0 + corner_weight
    chunks, found = [], 0
    for _ in range(max(100, 20 * n // BATCH)):
        xy = rng.uniform(-lim, lim, size=(BATCH, 2))
        weight = 1.0 + corner_weight * corner_mask(city, xy, corner_reach)
        keep = street_mask(city, xy, margin, region) & (rng.uniform(0.0, top, BATCH) < weight)
        chunks.append(xy[keep])
        found += int(keep.sum())
        if found >= n:
            break
    if found < n:
        raise RuntimeError(f"found only {found} street positions of {n} (margin {margin} m, "
                           f"region {region!r}): the streets are too narrow for the margin")
    xy = np.concatenate(chunks)[:n]
    yaw = -np.pi + 2.0 * np.pi * (rng.permutation(n) + rng.uniform(size=n)) / n
    return np.column_stack([xy, yaw])

