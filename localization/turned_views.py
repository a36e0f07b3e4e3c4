"""Test-time turns: one image's position from the same view turned by a pixel or two.

A perspective camera that turns about its vertical axis by a small angle sees nearly the
same picture shifted sideways: one pixel of a 64-pixel, 75-degree image is 1.17 degrees on
average (1.37 at the centre; psi* reads 1.08-1.17 per pixel on tuning cities 11-12). The
robot has not moved, so psi* of each shifted view estimates the same position, with errors
that differ from view to view (each view's features meet other training neighbours). The
median of the ``2 k + 1`` positions (shifts ``-k .. k``) is less spread than one view's:
on tuning cities 11-12 (the appearance benchmark's daylight map, 300 lane images per city and
preset, default / dusk / overcast / night) the share within (0.25 m, 2 deg) rose from 74.9 %
to 79.3 % (k = 1) and 80.7 % (k = 2) on average, within (0.5 m, 5 deg) from 93.0 to 95.6 %,
the coarsest share unchanged (docs/method.md §8.6). The heading stays the unshifted view's.

Only a perspective (pinhole) camera turns by a shift; a fisheye or catadioptric image turns
by another warp, so :func:`check_turn_camera` refuses them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from localization._validation import check_int
from localization.geometry import Array

__all__ = ["TURN_CAMERAS", "check_turn_camera", "median_position", "turned_prediction",
           "turned_view"]

#: cameras whose small turns are horizontal shifts of the image
TURN_CAMERAS = ("perspective",)


def turned_view(images: NDArray[np.uint8], pixels: int) -> NDArray[np.uint8]:
    """Images (n, H, W, C) shifted ``pixels`` columns to the right (left if negative), the
    uncovered edge columns repeating the nearest original column."""
    pixels = check_int(pixels, "pixels")
    width = images.shape[2]
    if abs(pixels) >= width:
        raise ValueError(f"pixels must be smaller than the image width {width}, got {pixels}")
    if pixels == 0:
        return images
    out = np.roll(images, pixels, axis=2)
    if pixels > 0:
        out[:, :, :pixels] = images[:, :, :1]
    else:
        out[:, :, pixels:] = images[:, :, -1:]
    return out


def median_position(poses: Array) -> Array:
    """Positions (n, 2): the median over the views of ``poses`` (views, n, 3), ignoring the
    views out of the training domain (NaN); NaN where every view is."""
    xy = poses[..., :2]
    out = np.full(xy.shape[1:], np.nan)
    ok = np.isfinite(xy).all(axis=2).any(axis=0)
    out[ok] = np.nanmedian(xy[:, ok], axis=0)
    return out


def check_turn_camera(camera: str | None) -> None:
    """ValueError unless ``camera`` turns by a shift (None: unknown, e.g. recorded data, is
    taken to be perspective)."""
    if camera is not None and camera not in TURN_CAMERAS:
        raise ValueError(f"turns apply to the cameras {TURN_CAMERAS} (a small turn shifts "
                         f"the image), not to {camera!r}; use turns=0")


def turned_prediction(predict: Callable[[NDArray[np.uint8]], Array], images: NDArray[np.uint8],
                      turns: int) -> Array:
    """``predict(images)`` (n, 3) with each position replaced by the median over the image
    and its views turned by 1..``turns`` pixels either way (rows the image itself has out of
    the domain stay NaN; the heading stays the image's own)."""
    poses = predict(images)
    if turns:
        views = np.stack([poses] + [predict(turned_view(images, s))
                                    for k in range(1, turns + 1) for s in (-k, k)])
        live = np.isfinite(poses).all(axis=1)
        poses[live, :2] = median_position(views[:, live])
    return poses
