"""What the camera itself does to an image: motion blur, exposure and sensor noise.

Applied to the rendered uint8 image in this order (a real sensor integrates the blurred
light, scales it by its gain, then adds read noise):

1. motion blur: during the exposure time ``T`` the camera turns by ``|w| T`` and moves by
   ``|v| T``; the image is smeared sideways over ``L = T (|w| f + |v| f / 2)`` pixels
   (``f`` the focal length in pixels; forward motion smears less than turning: scene
   points ~2 m away), a box filter along the rows. Standing still there is no blur.
2. exposure: pixel values times ``exposure`` (a lookup table), clipped to [0, 255].
3. noise: ``+ N(0, (255 noise)^2)`` per pixel and channel, rounded and clipped. The normal
   draws come from a :class:`NoiseBank`: four images' worth drawn once from the env's
   conditions stream, read from a random offset for every image (one generator call a
   frame instead of H W 3: a tenth of the cost), so the same seed gives the same noise.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import uniform_filter1d

from envs.conditions import Conditions

__all__ = ["NoiseBank", "apply_camera_effects", "blur_length", "focal_length_px"]


class NoiseBank:
    """Standard normal float32 draws for image-sized noise (see the module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator — draws the bank and the offsets.
    """

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._bank = np.zeros(0, np.float32)

    def __call__(self, shape: tuple[int, ...]) -> NDArray[np.float32]:
        """Standard normal values of ``shape`` (a view into the bank: do not modify)."""
        n = int(np.prod(shape))
        if len(self._bank) < 2 * n:
            self._bank = self.rng.standard_normal(4 * n, dtype=np.float32)
        o = int(self.rng.integers(0, len(self._bank) - n + 1))
        return self._bank[o : o + n].reshape(shape)


def blur_length(c: Conditions, v: float, w: float, focal_px: float) -> float:
    """Smear length in pixels for linear speed ``v`` (m/s) and turn rate ``w`` (rad/s)."""
    return c.motion_blur * (abs(w) * focal_px + 0.5 * abs(v) * focal_px)


def apply_camera_effects(image: NDArray[np.uint8], c: Conditions, v: float, w: float,
                         focal_px: float, noise: NoiseBank) -> NDArray[np.uint8]:
    """``image`` (H, W, 3) uint8 as the camera of ``c`` records it at speeds ``v``, ``w``.

    Returns the input array itself when ``c`` has no camera effects.
    """
    if not c.has_camera_effects:
        return image
    out = image
    if c.motion_blur > 0:
        n = round(blur_length(c, v, w, focal_px))
        if n >= 2:
            out = uniform_filter1d(out, size=n, axis=1, mode="nearest")
    if c.exposure != 1.0:
        lut = np.clip(np.arange(256) * c.exposure + 0.5, 0, 255).astype(np.uint8)
        out = lut[out]
    if c.noise > 0:
        noisy = noise(out.shape) * np.float32(255.0 * c.noise)
        noisy += out
        noisy += np.float32(0.5)
        out = np.clip(noisy, 0, 255, out=noisy).astype(np.uint8)
    return out


def focal_length_px(fovy_deg: float, height: int) -> float:
    """Focal length in pixels of a pinhole camera with vertical field of view ``fovy_deg``."""
    return 0.5 * height / math.tan(math.radians(0.5 * fovy_deg))
