"""Robot cameras: a registry of named camera factories.

Every camera is built as ``factory(model, image_size, camera_name="ego")`` and
offers ``render(data) -> (H, W, 3) uint8`` and ``close()``. ``"perspective"``
renders MuJoCo's pinhole camera ``"ego"`` directly; ``"fisheye"`` and
``"catadioptric"`` are registered from :mod:`envs.cube_camera` (cube map +
projection) when that module is available.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, Protocol

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["CAMERAS", "Camera", "PerspectiveCamera", "TopDownView", "check_image_size", "make_camera", "register_camera"]

# Mesa's software rasterizer (llvmpipe) splits each frame over worker threads; for the
# small frames here the hand-off costs more than it saves (64x64: ~890 -> ~1170 env
# steps/s on 2 shared cores; a wash at 128x128). Must be set before the first GL context
# exists, i.e. on import; a value already in the environment wins.
os.environ.setdefault("LP_NUM_THREADS", "0")

MIN_IMAGE_SIDE = 16
MAX_IMAGE_SIDE = 1024

# render flags that cost time in software GL and add nothing to this scene
_OFF_FLAGS = ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_SKYBOX", "mjRND_FOG", "mjRND_HAZE")


class Camera(Protocol):
    """What the env needs from a camera."""

    def render(self, data: mujoco.MjData) -> NDArray[np.uint8]: ...

    def close(self) -> None: ...


def check_image_size(image_size: object, name: str = "image_size") -> tuple[int, int]:
    """Validate ``(H, W)`` and return it as a tuple of ints.

    Raises
    ------
    TypeError
        If it is not a pair of integers.
    ValueError
        If a side is outside ``[MIN_IMAGE_SIDE, MAX_IMAGE_SIDE]`` or it has another length.
    """
    if isinstance(image_size, (str, bytes)) or not hasattr(image_size, "__len__"):
        raise TypeError(f"{name} must be a pair (H, W) of integers, got {image_size!r}")
    if len(image_size) != 2:  # type: ignore[arg-type]
        raise ValueError(f"{name} must be a pair (H, W) of integers, got {image_size!r}")
    h, w = image_size  # type: ignore[misc]
    for v in (h, w):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"{name} must contain integers, got {image_size!r}")
        if not MIN_IMAGE_SIDE <= v <= MAX_IMAGE_SIDE:
            raise ValueError(
                f"{name} sides must be in [{MIN_IMAGE_SIDE}, {MAX_IMAGE_SIDE}] pixels, got {image_size!r}"
            )
    return int(h), int(w)


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """Return a ``mujoco.Renderer`` with the offscreen buffer grown to fit and costly flags off."""
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    renderer = mujoco.Renderer(model, height, width)
    for flag in _OFF_FLAGS:
        renderer.scene.flags[getattr(mujoco.mjtRndFlag, flag)] = 0
    return renderer


class PerspectiveCamera:
    """A pinhole camera: MuJoCo's own render of the named model camera.

    Parameters
    ----------
    model : mujoco.MjModel
    image_size : (H, W) ints.
    camera_name : str — a camera in ``model`` (default ``"ego"``).
    """

    def __init__(self, model: mujoco.MjModel, image_size: tuple[int, int], camera_name: str = "ego") -> None:
        self.image_size = check_image_size(image_size)
        self.camera_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera_name)
        if self.camera_id < 0:
            raise ValueError(f"model has no camera named {camera_name!r}")
        self._renderer: mujoco.Renderer | None = make_renderer(model, *self.image_size)

    def render(self, data: mujoco.MjData) -> NDArray[np.uint8]:
        """Return the camera image, shape (H, W, 3) uint8 (a fresh array)."""
        if self._renderer is None:
            raise RuntimeError("camera is closed")
        self._renderer.update_scene(data, camera=self.camera_id)
        return self._renderer.render()

    def gl_targets(self) -> list[tuple[mujoco.MjvScene, mujoco.MjrContext]]:
        """The (scene, GL context) pairs it renders with (``envs.lighting`` sets their fog)."""
        if self._renderer is None:
            raise RuntimeError("camera is closed")
        return [(self._renderer.scene, self._renderer._mjr_context)]

    def close(self) -> None:
        """Free the GL context (idempotent)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


CameraFactory = Callable[..., Camera]
CAMERAS: dict[str, CameraFactory] = {"perspective": PerspectiveCamera}


def register_camera(name: str, factory: CameraFactory) -> None:
    """Register ``factory(model, image_size, camera_name="ego")`` under ``name``."""
    CAMERAS[name] = factory


def make_camera(name: str, model: mujoco.MjModel, image_size: tuple[int, int], **kwargs: object) -> Camera:
    """Build the registered camera ``name`` for ``model``.

    Raises
    ------
    ValueError
        If ``name`` is not registered (the message lists the known names) or the size is bad.
    """
    if not isinstance(name, str):
        raise TypeError(f"camera must be a camera name (str), got {type(name).__name__}")
    if name not in CAMERAS:
        raise ValueError(f"unknown camera {name!r}; known cameras: {sorted(CAMERAS)}")
    return CAMERAS[name](model, check_image_size(image_size), **kwargs)


def _register_cube_cameras() -> None:
    try:
        from envs.cube_camera import CubeMapCamera
    except ModuleNotFoundError as err:  # the cube-map module is not there (yet)
        if err.name != "envs.cube_camera":
            raise
        return

    for projection in ("fisheye", "catadioptric"):
        def factory(model, image_size, camera_name="ego", _p=projection, **kw):  # type: ignore[no-untyped-def]
            return CubeMapCamera(model, image_size, projection=_p, camera_name=camera_name, **kw)

        register_camera(projection, factory)


_register_cube_cameras()


class TopDownView:
    """A north-up numpy raster of a city with the robot and the goal drawn on it (for ``render()``).

    Parameters
    ----------
    city : envs.scene.City
    pixels : int, optional — side of the square image; default :data:`MAP_PIXELS_PER_METRE`
        per metre of city side, at least 256 (256 for the default 20 m city, 768 for 60 m:
        streets stay 25 pixels wide, the goal disc 13).
    """

    ROBOT = np.array([255, 255, 255], np.uint8)
    HEADING = np.array([230, 30, 30], np.uint8)
    GOAL = np.array([30, 220, 60], np.uint8)
    #: map pixels per metre of city side when ``pixels`` is not given
    MAP_PIXELS_PER_METRE = 12.8

    def __init__(self, city: Any, pixels: int | None = None) -> None:
        if pixels is None:
            pixels = max(256, round(self.MAP_PIXELS_PER_METRE * city.size))
        self.city, self.pixels = city, int(pixels)
        lo, hi = city.bounds
        centres = lo + (np.arange(self.pixels) + 0.5) * (hi - lo) / self.pixels
        self._x, self._y = np.meshgrid(centres, centres[::-1])  # row 0 is north
        self._px = (hi - lo) / self.pixels
        base = city.ground_image(self.pixels, extent=city.half)
        for b in city.buildings:
            (cx, cy, _), (hx, hy, _) = b.center, b.half_size
            mask = (np.abs(self._x - cx) < hx) & (np.abs(self._y - cy) < hy)
            base[mask] = (np.asarray(b.rgb) * 255).astype(np.uint8)
        self._base = base

    def draw(self, pose: NDArray[np.float64], goal: NDArray[np.float64]) -> NDArray[np.uint8]:
        """Return the (pixels, pixels, 3) uint8 map with the goal disc and the robot (disc + heading)."""
        img = self._base.copy()
        img[self._disc(goal[0], goal[1], 0.5)] = self.GOAL
        x, y, yaw = pose
        img[self._disc(x, y, max(0.22, 3 * self._px))] = self.ROBOT
        for t in np.linspace(0.0, 0.45, 10):
            img[self._disc(x + t * np.cos(yaw), y + t * np.sin(yaw), max(0.05, self._px))] = self.HEADING
        return img

    def _disc(self, x: float, y: float, r: float) -> NDArray[np.bool_]:
        return (self._x - x) ** 2 + (self._y - y) ** 2 <= r * r
