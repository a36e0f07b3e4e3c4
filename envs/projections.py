"""Omnidirectional camera models built from a cube map: pure numpy geometry.

MuJoCo renders only perspective cameras (``fovy < 180``), so the fisheye and
catadioptric cameras are resampled from a cube map: six 90-degree perspective
faces rendered from the camera position, gathered into one image by a
precomputed lookup table (:func:`envs.cube_atlas.build_lut`, :func:`envs.cube_atlas.remap`).

Conventions
-----------
Directions are unit 3-vectors in the **camera frame** of MuJoCo / OpenGL:
``x`` right, ``y`` up, the camera looks along ``-z``. A camera-frame vector
``d`` is ``cam_xmat @ d`` in the world frame.

Images are ``(H, W, 3)``; pixel ``(row i, column j)`` covers the continuous
pixel coordinates ``u in [j, j + 1)``, ``v in [i, i + 1)`` (``u`` to the right,
``v`` down), so its centre is ``(u, v) = (j + 0.5, i + 0.5)`` and the image
centre is ``(cx, cy) = (W / 2, H / 2)``. The circular images have radius
``R = min(H, W) / 2``.

The cube map and its lookup table are in :mod:`envs.cube_atlas`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from envs.cube_atlas import (
    _pixel_centres,
    _unit,
    image_shape,
)

PROJECTIONS: tuple[str, ...] = ("fisheye", "catadioptric")


def _check_fov(fov: float) -> float:
    if not (np.isfinite(fov) and 0.0 < fov < 360.0):
        raise ValueError(f"fisheye fov must be in (0, 360) degrees, got {fov}")
    return float(fov)


def fisheye_focal(size: int | tuple[int, int], fov: float = 190.0) -> float:
    """Focal length ``f = R / (fov / 2)`` in pixels per radian (``R = min(H, W) / 2``)."""
    h, w = image_shape(size)
    return min(h, w) / 2.0 / np.deg2rad(_check_fov(fov) / 2.0)


def fisheye_directions(
    size: int | tuple[int, int], fov: float = 190.0
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixel directions of an equidistant fisheye: ``r = f * angle_from_axis``.

    A pixel centre at offset ``(x, y)`` from the image centre (x right, y up) has
    radius ``r = sqrt(x^2 + y^2)``, off-axis angle ``t = r / f`` and azimuth
    ``p = atan2(y, x)``; its direction is ``(sin t cos p, sin t sin p, -cos t)``.
    The image is a disc of radius ``R = f * fov / 2``: pixels with ``r > R``
    (``t > fov / 2``) are invalid (black).

    Parameters
    ----------
    size : int or (H, W)
    fov : float
        Full field of view in degrees, in (0, 360); 180 sees the front hemisphere.

    Returns
    -------
    directions : ndarray of float64, shape (H, W, 3)
        Unit camera-frame directions (also defined outside the disc).
    valid : ndarray of bool, shape (H, W)
        The image disc.
    """
    hw = image_shape(size)
    f = fisheye_focal(hw, fov)
    x, y = _pixel_centres(hw)
    r = np.hypot(x, y)
    t = r / f
    with np.errstate(invalid="ignore", divide="ignore"):
        cp, sp = np.where(r > 0, x / r, 1.0), np.where(r > 0, y / r, 0.0)
    d = np.stack([np.sin(t) * cp, np.sin(t) * sp, -np.cos(t)], axis=-1)
    return d, r <= min(hw) / 2.0


def fisheye_project(
    directions: ArrayLike, size: int | tuple[int, int], fov: float = 190.0
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Project camera-frame directions into the equidistant fisheye image.

    ``t = atan2(sqrt(x^2 + y^2), -z)``, ``r = f t``,
    ``u = cx + r x / sqrt(x^2 + y^2)``, ``v = cy - r y / sqrt(x^2 + y^2)``
    (the optical axis ``-z`` lands on the centre ``(W/2, H/2)``). ``directions`` has
    shape (..., 3); ``size`` and ``fov`` as in :func:`fisheye_directions`.

    Returns
    -------
    uv : ndarray of float64, shape (..., 2)
        Continuous pixel coordinates ``(u, v)``; pixel ``(int(v), int(u))``.
    visible : ndarray of bool, shape (...)
        ``t <= fov / 2`` (the direction is inside the image disc).
    """
    h, w = image_shape(size)
    f = fisheye_focal((h, w), fov)
    d = _unit(directions)
    rho = np.hypot(d[..., 0], d[..., 1])
    t = np.arctan2(rho, -d[..., 2])
    with np.errstate(invalid="ignore", divide="ignore"):
        cp = np.where(rho > 0, d[..., 0] / rho, 1.0)
        sp = np.where(rho > 0, d[..., 1] / rho, 0.0)
    uv = np.stack([w / 2.0 + f * t * cp, h / 2.0 - f * t * sp], axis=-1)
    return uv, t <= np.deg2rad(fov) / 2.0 + 1e-12


# ----------------------------------------------------------------------------- catadioptric
def _ring(
    hw: tuple[int, int], elevation_range: tuple[float, float], radii: tuple[float, float]
) -> tuple[float, float, float, float]:
    lo, hi = (float(e) for e in elevation_range)
    if not (-90.0 <= lo < hi <= 90.0):
        raise ValueError(
            f"elevation_range must satisfy -90 <= low < high <= 90, got {elevation_range}"
        )
    r_in, r_out = (float(r) for r in radii)
    if not (0.0 <= r_in < r_out <= 1.0):
        raise ValueError(f"ring radii must satisfy 0 <= inner < outer <= 1, got {radii}")
    big_r = min(hw) / 2.0
    return np.deg2rad(lo), np.deg2rad(hi), r_in * big_r, r_out * big_r


def catadioptric_directions(
    size: int | tuple[int, int],
    elevation_range: tuple[float, float] = (-20.0, 40.0),
    radii: tuple[float, float] = (0.3, 1.0),
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixel directions of a panoramic annulus (a camera looking at a convex mirror).

    Azimuth ``az`` is measured from the optical axis (``-z``, forward) towards the
    left (``-x``), i.e. counter-clockwise seen from above (``+y``), like yaw.
    Elevation ``el`` is the angle above the camera's horizontal ``x-z`` plane. The
    direction is ``(-sin az cos el, sin el, -cos az cos el)``. The image is a map
    view with the robot facing up: ``u = cx - r sin az``, ``v = cy - r cos az``
    (forward at the top, left at the left, behind at the bottom), and elevation is
    linear in radius, ``r = r_in + (el - el_lo) / (el_hi - el_lo) (r_out - r_in)``
    (horizon-low elevations inside, high outside, as with a mirror above the lens).
    Pixels outside ``r_in <= r <= r_out`` are invalid (black).

    Parameters
    ----------
    size : int or (H, W)
    elevation_range : (float, float)
        ``(el_lo, el_hi)`` in degrees, at the inner and the outer ring.
    radii : (float, float)
        Inner and outer ring radius as fractions of ``R = min(H, W) / 2``.

    Returns
    -------
    directions : ndarray of float64, shape (H, W, 3)
    valid : ndarray of bool, shape (H, W)
        The annulus.
    """
    hw = image_shape(size)
    lo, hi, r_in, r_out = _ring(hw, elevation_range, radii)
    x, y = _pixel_centres(hw)
    r = np.hypot(x, y)
    az = np.arctan2(-x, y)
    el = lo + (r - r_in) / (r_out - r_in) * (hi - lo)
    d = np.stack([-np.sin(az) * np.cos(el), np.sin(el), -np.cos(az) * np.cos(el)], axis=-1)
    return d, (r >= r_in) & (r <= r_out)


def catadioptric_project(
    directions: ArrayLike,
    size: int | tuple[int, int],
    elevation_range: tuple[float, float] = (-20.0, 40.0),
    radii: tuple[float, float] = (0.3, 1.0),
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Project camera-frame directions into the catadioptric ring image.

    ``az = atan2(-x, -z)``, ``el = asin(y)`` (unit ``d``), then ``r`` and ``(u, v)``
    as in :func:`catadioptric_directions`, which documents the other parameters;
    ``directions`` has shape (..., 3).

    Returns
    -------
    uv : ndarray of float64, shape (..., 2)
        Continuous pixel coordinates ``(u, v)`` (elevations outside the range map
        to radii outside the ring, linearly extrapolated).
    visible : ndarray of bool, shape (...)
        ``el_lo <= el <= el_hi``.
    """
    h, w = image_shape(size)
    lo, hi, r_in, r_out = _ring((h, w), elevation_range, radii)
    d = _unit(directions)
    az = np.arctan2(-d[..., 0], -d[..., 2])
    el = np.arcsin(np.clip(d[..., 1], -1.0, 1.0))
    r = r_in + (el - lo) / (hi - lo) * (r_out - r_in)
    uv = np.stack([w / 2.0 - r * np.sin(az), h / 2.0 - r * np.cos(az)], axis=-1)
    return uv, (el >= lo - 1e-12) & (el <= hi + 1e-12)


def projection_directions(
    projection: str, size: int | tuple[int, int], **kw: object
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Dispatch to :func:`fisheye_directions` / :func:`catadioptric_directions` by name."""
    if projection == "fisheye":
        return fisheye_directions(size, **kw)  # type: ignore[arg-type]
    if projection == "catadioptric":
        return catadioptric_directions(size, **kw)  # type: ignore[arg-type]
    raise ValueError(f"unknown projection {projection!r}; options: {', '.join(PROJECTIONS)}")


# ----------------------------------------------------------------------------- lookup table
