"""Fisheye and catadioptric cameras for MuJoCo, resampled from a cube map.

MuJoCo renders only perspective cameras with ``fovy < 180``. A
:class:`CubeMapCamera` renders the six 90-degree faces of a cube map from the
pose of a model camera (``data.cam_xpos`` / ``data.cam_xmat``) into one atlas
(one ``mjv_updateScene``, six ``mjr_render`` calls into six viewports of one
offscreen buffer, one ``mjr_readPixels``), then resamples the atlas into the
omnidirectional image with a lookup table precomputed by
:mod:`envs.projections` (one ``np.take`` gather plus a bilinear weighted sum).

The model camera's own ``fovy`` is ignored: only its pose is used; its frame
(x right, y up, looking along -z) is the frame of :mod:`envs.projections`.
Lights, including the headlight, stay fixed in the world while the faces are
rendered, so shading is continuous across the face seams.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

# (importing this module runs envs/__init__.py first, which sets MUJOCO_GL before mujoco loads)
import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.cube_atlas import FACE_AXES, CubeLUT, build_lut, image_shape, remap
from envs.projections import PROJECTIONS, fisheye_focal, projection_directions

_KWARGS = {"fisheye": ("fov",), "catadioptric": ("elevation_range", "radii")}
_GRID = (2, 3)  # atlas of faces: 2 rows x 3 columns (fits the default 640 x 480 buffer)
#: Scene flags switched off by default: shadows and reflections are re-rendered for each of
#: the 6 faces (6x their cost in software GL); fog and haze depend on the view direction
#: (they would show the face seams). Skybox off as for the env's perspective camera.
DEFAULT_RENDER_FLAGS: dict[str, bool] = {
    "mjRND_SHADOW": False,
    "mjRND_REFLECTION": False,
    "mjRND_SKYBOX": False,
    "mjRND_FOG": False,
    "mjRND_HAZE": False,
}


def default_face_size(
    projection: str, image_size: int | tuple[int, int], **projection_kw: Any
) -> int:
    """Cube face size matching the output's angular resolution at the face centres.

    A face of ``F`` pixels spans ``tan`` in ``[-1, 1]``, so it has ``F / 2`` pixels
    per radian at its centre (``F / 4`` at its corners). The fisheye has
    ``f = R / (fov / 2)`` pixels per radian; the catadioptric ring has ``r_out`` per
    radian of azimuth on its outer edge and ``(r_out - r_in) / (el_hi - el_lo)``
    per radian of elevation. ``F = ceil(2 * max resolution)``, at least 8.

    Returns
    -------
    int
    """
    _check_projection(projection, projection_kw)
    h, w = image_shape(image_size)
    if projection == "fisheye":
        px_per_rad = fisheye_focal((h, w), **projection_kw)
    else:
        lo, hi = projection_kw.get("elevation_range", (-20.0, 40.0))
        r_in, r_out = projection_kw.get("radii", (0.3, 1.0))
        big_r = min(h, w) / 2.0
        px_per_rad = max(r_out * big_r, (r_out - r_in) * big_r / math.radians(hi - lo))
    return max(8, math.ceil(2.0 * px_per_rad))


def _check_projection(projection: str, projection_kw: dict[str, Any]) -> None:
    if projection not in PROJECTIONS:
        raise ValueError(f"unknown projection {projection!r}; options: {', '.join(PROJECTIONS)}")
    unknown = set(projection_kw) - set(_KWARGS[projection])
    if unknown:
        raise ValueError(
            f"unknown option(s) {sorted(unknown)} for projection {projection!r}; "
            f"options: {', '.join(_KWARGS[projection])}"
        )


class CubeMapCamera:
    """An omnidirectional camera attached to a MuJoCo model camera.

    Parameters
    ----------
    model : mujoco.MjModel
    image_size : int or (H, W)
        Output image size in pixels (the circle / ring has radius ``min(H, W) / 2``).
    projection : {"fisheye", "catadioptric"}
    camera_name : str
        Model camera whose pose (``data.cam_xpos``, ``data.cam_xmat``) is used.
    face_size : int, optional
        Pixels across one 90-degree cube face; default :func:`default_face_size`.
    bilinear : bool
        Bilinear (default) or nearest-neighbour resampling.
    scene_option : mujoco.MjvOption, optional
        Visualisation options (e.g. geom groups) for the scene.
    render_flags : mapping of str to bool, optional
        ``mjtRndFlag`` names to set on the scene, e.g. ``{"mjRND_SHADOW": True}``;
        applied on top of :data:`DEFAULT_RENDER_FLAGS`.
    **projection_kw
        ``fov`` (degrees, default 190) for the fisheye; ``elevation_range``
        (degrees, default (-20, 40)) and ``radii`` (fractions of ``min(H, W) / 2``,
        default (0.3, 1.0)) for the catadioptric ring; see :mod:`envs.projections`.

    Attributes
    ----------
    lut : CubeLUT
        The lookup table (``lut.mask`` is the valid disc / annulus).
    face_size : int
    faces : tuple of int
        The cube faces rendered (indices into ``envs.projections.FACE_AXES``); faces the
        table never samples are skipped.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        image_size: int | tuple[int, int],
        projection: str = "fisheye",
        camera_name: str = "ego",
        face_size: int | None = None,
        *,
        bilinear: bool = True,
        scene_option: mujoco.MjvOption | None = None,
        render_flags: Mapping[str, bool] | None = None,
        **projection_kw: Any,
    ) -> None:
        self._con: mujoco.MjrContext | None = None
        self._gl: Any = None
        _check_projection(projection, projection_kw)
        self.image_shape = image_shape(image_size)
        cam_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera_name)
        if cam_id < 0:
            raise ValueError(f"model has no camera named {camera_name!r}")
        if face_size is None:
            face_size = default_face_size(projection, self.image_shape, **projection_kw)
        if not (isinstance(face_size, (int, np.integer)) and 1 <= face_size <= 4096):
            raise ValueError(f"face_size must be an int in [1, 4096], got {face_size!r}")
        flags = {**DEFAULT_RENDER_FLAGS, **(render_flags or {})}
        unknown = [f for f in flags if not hasattr(mujoco.mjtRndFlag, f)]
        if unknown:
            raise ValueError(f"unknown render flag(s) {unknown}; see mujoco.mjtRndFlag")

        self.model, self.projection, self.camera_name = model, projection, camera_name
        self.face_size, self._cam_id = int(face_size), cam_id
        pad = 1
        g = self._g = self.face_size + 2 * pad
        rows, cols = _GRID
        self._atlas_hw = (rows * g, cols * g)

        directions, valid = projection_directions(projection, self.image_shape, **projection_kw)
        lut = build_lut(directions, self.face_size, valid, pad=pad, bilinear=bilinear, grid=_GRID)
        # OpenGL reads rows bottom-up: index the raw buffer instead of flipping every frame.
        ha, wa = self._atlas_hw
        row, col = np.divmod(lut.index, wa)
        raw_index = np.ascontiguousarray((ha - 1 - row) * wa + col)
        self.lut = CubeLUT(raw_index, lut.weight, lut.mask, lut.face_size, lut.pad, lut.grid)
        # Render only the faces the table samples (e.g. a 190-degree fisheye never sees the
        # back face); face k's grid cell (r, c) is the GL viewport (left, bottom) = (c G, (rows-1-r) G).
        used = lut.index[lut.weight[..., 0] > 0]
        cells = (used // wa) // g * cols + (used % wa) // g
        self.faces = tuple(int(k) for k in np.unique(cells))
        self._rects = {}
        for k in self.faces:
            r, c = divmod(k, cols)
            self._rects[k] = mujoco.MjrRect(c * g, (rows - 1 - r) * g, g, g)
        self._full = mujoco.MjrRect(0, 0, wa, ha)
        self._raw = np.zeros((ha, wa, 3), np.uint8)
        self._half_extent = g / self.face_size  # frustum half-size / near: tan(45 deg) * G / F

        self._scene = mujoco.MjvScene(model, maxgeom=10000)
        for name, on in flags.items():
            self._scene.flags[getattr(mujoco.mjtRndFlag, name)] = int(bool(on))
        self._option = scene_option if scene_option is not None else mujoco.MjvOption()
        self._mjv_cam = mujoco.MjvCamera()
        self._mjv_cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._mjv_cam.fixedcamid = cam_id
        self._gl = mujoco.GLContext(wa, ha)
        self._gl.make_current()
        vis = model.vis.global_
        old = (vis.offwidth, vis.offheight)
        try:  # the offscreen buffer is sized from the model when the context is made
            vis.offwidth, vis.offheight = max(old[0], wa), max(old[1], ha)
            self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        finally:
            vis.offwidth, vis.offheight = old
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._con)

    @property
    def scene(self) -> mujoco.MjvScene:
        """The ``mjvScene`` rendered (its ``flags`` persist across frames)."""
        return self._scene

    def gl_targets(self) -> list[tuple[mujoco.MjvScene, mujoco.MjrContext]]:
        """The (scene, GL context) pair it renders with (``envs.lighting`` sets their fog)."""
        if self._con is None:
            raise RuntimeError("camera is closed")
        return [(self._scene, self._con)]

    @property
    def mask(self) -> NDArray[np.bool_]:
        """(H, W) bool: the pixels that see the scene (disc or annulus)."""
        return self.lut.mask

    def render_cube(self, data: mujoco.MjData) -> NDArray[np.uint8]:
        """Render the six faces; return the raw atlas (OpenGL rows, bottom-up).

        Returns
        -------
        ndarray of uint8, shape (2 G, 3 G, 3) with ``G = face_size + 2``; ``np.flipud``
        of it is the atlas of :func:`envs.projections.atlas_directions` (cells of faces
        not in :attr:`faces` are undefined). The array is reused by the next call.
        """
        if self._con is None:
            raise RuntimeError("render called after close()")
        self._gl.make_current()
        mujoco.mjv_updateScene(
            self.model, data, self._option, None, self._mjv_cam,
            mujoco.mjtCatBit.mjCAT_ALL, self._scene,
        )  # fmt: skip
        pos = data.cam_xpos[self._cam_id]
        axes = FACE_AXES @ data.cam_xmat[self._cam_id].reshape(3, 3).T  # (6, 3, 3) world
        cams = self._scene.camera
        near = cams[0].frustum_near
        for k, rect in self._rects.items():
            for cam in cams:  # both stereo eyes at the camera position (no ipd offset)
                cam.pos[:] = pos
                cam.forward[:] = axes[k, 0]
                cam.up[:] = axes[k, 2]
                cam.frustum_center = 0.0
                cam.frustum_bottom = -near * self._half_extent
                cam.frustum_top = near * self._half_extent
                cam.orthographic = 0
            mujoco.mjr_render(rect, self._scene, self._con)
        mujoco.mjr_readPixels(self._raw, None, self._full, self._con)
        return self._raw

    def render(self, data: mujoco.MjData) -> NDArray[np.uint8]:
        """Render the omnidirectional image.

        Parameters
        ----------
        data : mujoco.MjData
            After ``mj_forward`` / ``mj_step`` (uses ``cam_xpos``, ``cam_xmat``).

        Returns
        -------
        ndarray of uint8, shape (H, W, 3); black outside :attr:`mask`.
        """
        return remap(self.render_cube(data), self.lut)

    def close(self) -> None:
        """Free the OpenGL resources (idempotent)."""
        if self._con is not None:
            if self._gl is not None:
                self._gl.make_current()
            self._con.free()
            self._con = None
        if self._gl is not None:
            self._gl.free()
            self._gl = None

    def __enter__(self) -> CubeMapCamera:  # noqa: PYI034
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001, S110  (interpreter shutdown: GL may be gone)
            pass

    def __repr__(self) -> str:
        return (
            f"CubeMapCamera(projection={self.projection!r}, image_size={self.image_shape}, "
            f"camera_name={self.camera_name!r}, face_size={self.face_size})"
        )
