"""Camera masks: which pixels of a camera image look at what (elevation of each pixel's ray).

Used by the paper's experiment for the masked PixelPCA (:func:`ground_mask` hides the near
road, whose texture moves fastest and repeats: lane dashes).
"""

from __future__ import annotations

import numpy as np

from envs.projections import projection_directions
from envs.robot import CAMERA_FOVY, CAMERA_HEIGHT

__all__ = ["elevation_map", "ground_mask"]


def elevation_map(camera: str, size: int) -> np.ndarray:
    """Elevation (degrees above the horizontal) of every pixel's ray, NaN outside the image.

    Parameters
    ----------
    camera : a registered camera name ("perspective", "fisheye", "catadioptric", ...).
    size : side of the square image (pixels).

    Returns
    -------
    (size, size) float64 array.
    """
    if camera == "perspective":
        f = (size / 2) / np.tan(np.radians(CAMERA_FOVY) / 2)
        c = size / 2 - (np.arange(size) + 0.5)  # up / right from the centre
        up, right = np.meshgrid(c, -c, indexing="ij")
        return np.degrees(np.arctan2(up, np.hypot(right, f)))
    d, valid = projection_directions(camera, size)
    el = np.degrees(np.arcsin(np.clip(d[..., 1], -1.0, 1.0)))
    el[~valid] = np.nan
    return el


def ground_mask(camera: str, size: int, ground_range: float) -> np.ndarray:
    """(size, size) bool: pixels that do not see the ground within ``ground_range`` metres
    (camera at ``CAMERA_HEIGHT``): the near road texture moves fastest and repeats (lane
    dashes)."""
    return elevation_map(camera, size) >= -np.degrees(np.arctan2(CAMERA_HEIGHT, ground_range))
