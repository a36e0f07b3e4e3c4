"""Put a :class:`~envs.conditions.Conditions` into the compiled model and the cameras.

Everything changes through model parameters read at every frame (the sun light, the
headlight, material colours and glow) and through the renderers' fog settings, never by
re-uploading textures, so a new look costs microseconds and conditions can change between
two images.

- sun: the light ``"sun"``'s direction and diffuse colour;
- ambient and headlight: ``model.vis.headlight`` (MuJoCo's headlight rides on the camera:
  it is the robot's own light);
- horizon: the tint (``mat_rgba``) and glow (``mat_emission``) of the four horizon walls;
- seasonal: the ground material's tint and a per-building tint
  ``1 - facades * u_b`` with ``u_b`` uniform in [0, 1]^3 drawn from ``(city seed, season)``;
- street lamps (:func:`lamps_xml`, in the model only when the conditions can light them)
  over every intersection: pools of light on the ground (a second, glowing ground texture)
  and the glowing heads of the nearest lamps ahead; off, the floor has its own texture and
  the heads are fully transparent, which MuJoCo does not draw;
- fog: linear fog from ``start`` to ``end`` metres in ``fog_colour`` (``mjRND_FOG`` on the
  cameras' scenes, the distances and colour in their GL contexts).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.conditions import Conditions

__all__ = ["LAMP_HEIGHT", "Lighting", "lamp_ground_image", "lamp_positions", "lamps_xml",
           "paint_texture"]

LAMP_HEIGHT = 2.6  # m
LAMP_POOL_RADIUS = 1.1  # m, 1/e radius of a lamp's pool of light on the ground
LAMP_HEADS = 3  # lamp heads drawn: the nearest ones ahead of the camera
_LAMP_RGB = np.array([1.0, 0.85, 0.55])
_POOL_EMISSION = 1.0  # glow of the lit ground at lamps = 1


def lamp_positions(city: Any) -> NDArray[np.float64]:
    """(k, 2) street-lamp positions: the intersections of the street graph."""
    nodes, _ = city.street_graph()
    return np.asarray(nodes, dtype=np.float64)


def lamps_xml(city: Any) -> tuple[str, str]:
    """(assets, world geoms) XML of the street lamps (visual only: no collisions).

    Every geom costs a draw call, so the lamps' light on the ground is a second ground
    texture (pools of warm light painted around every lamp, :func:`lamp_ground_image`) that
    the floor switches to, glowing, while the lamps are lit; and only ``LAMP_HEADS`` glowing
    heads exist, moved to the lamps nearest ahead of the camera before every image
    (:meth:`Lighting.place_heads`).
    """
    pixels = city.ground_pixels()
    assets = (f'<texture name="ground_lamps" type="2d" builtin="flat" width="{pixels}" '
              f'height="{pixels}" rgb1="0.3 0.3 0.3"/>\n'
              '<material name="ground_lamps" texture="ground_lamps" texrepeat="1 1"/>\n'
              '<material name="lamp_head" rgba="1 0.85 0.55 0" emission="1"/>')
    geoms = [f'<geom name="lamp_head{j}" type="box" size="0.12 0.12 0.06" '
             f'pos="0 0 {LAMP_HEIGHT}" material="lamp_head" contype="0" conaffinity="0" '
             'group="2"/>' for j in range(LAMP_HEADS)]
    return assets, "\n".join(geoms)


def lamp_ground_image(city: Any, pixels: int) -> NDArray[np.uint8]:
    """The ground of :meth:`City.ground_image` with a pool of lamp light around every lamp,
    (pixels, pixels, 3) uint8."""
    day = city.ground_image(pixels).astype(np.float32) / 255.0
    e = city.floor_half()
    ticks = (-e + (np.arange(pixels) + 0.5) * (2 * e / pixels)).astype(np.float32)
    x, y = ticks[None, :], ticks[::-1, None]
    pool = np.zeros((pixels, pixels), np.float32)
    for lx, ly in lamp_positions(city):
        np.maximum(pool, np.exp(-((x - lx) ** 2 + (y - ly) ** 2) / LAMP_POOL_RADIUS ** 2), out=pool)
    p = (0.85 * pool)[..., None]
    lit = (1.0 - p) * 0.35 * day + p * _LAMP_RGB.astype(np.float32)
    return (np.clip(lit, 0.0, 1.0) * 255).astype(np.uint8)


def _ids(model: mujoco.MjModel, kind: mujoco.mjtObj, names: list[str]) -> NDArray[np.int_]:
    ids = [mujoco.mj_name2id(model, kind, n) for n in names]
    return np.array([i for i in ids if i >= 0], dtype=int)


class Lighting:
    """Applies conditions to one model (and the cameras that render it).

    Parameters
    ----------
    model : mujoco.MjModel — a city model (``City.to_mjcf``), with lamps if ``lamps_xml``
        went into it.
    city : envs.scene.City — for the seeds of the seasonal facade tints.

    The model's values when this is made are today's look: :meth:`apply` of the default
    conditions writes them back unchanged.
    """

    def __init__(self, model: mujoco.MjModel, city: Any) -> None:
        self.model, self.city = model, city
        mat = mujoco.mjtObj.mjOBJ_MATERIAL
        self._sun = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_LIGHT, "sun")
        self._sky = _ids(model, mat, [f"sky{s}" for s in "ENWS"])
        self._ground = _ids(model, mat, ["ground"])
        self._facade = _ids(model, mat, [f"mat{i}" for i in range(len(city.buildings))])
        self._lamp_head = _ids(model, mat, ["lamp_head"])
        self._floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
        self._floor_mat = (int(model.geom_matid[self._floor]),
                           int(mujoco.mj_name2id(model, mat, "ground_lamps")))
        self._heads = _ids(model, mujoco.mjtObj.mjOBJ_GEOM,
                           [f"lamp_head{j}" for j in range(LAMP_HEADS)])
        self._lamps = lamp_positions(city)
        self.lamps_on = False
        if self._floor_mat[1] >= 0:
            paint_texture(model, "ground_lamps", lamp_ground_image(city, city.ground_pixels()))
        self._default = {"dir": model.light_dir[self._sun].copy(),
                         "rgba": model.mat_rgba.copy(), "emission": model.mat_emission.copy()}
        self._season: tuple[int, NDArray[np.float64]] | None = None

    def apply(self, c: Conditions, data: mujoco.MjData, cameras: list[Any]) -> None:
        """Write ``c`` into the model, ``data``'s light frame and the cameras' fog."""
        m = self.model
        d = Conditions()
        if c.sun_direction == d.sun_direction:
            direction = self._default["dir"]
        else:
            direction = np.asarray(c.sun_direction) / np.linalg.norm(c.sun_direction)
        m.light_dir[self._sun] = direction
        data.light_xdir[self._sun] = direction  # the sun hangs on the world: no kinematics
        m.light_diffuse[self._sun] = c.sun
        m.vis.headlight.ambient[:] = c.ambient
        m.vis.headlight.diffuse[:] = c.headlight
        m.mat_rgba[:] = self._default["rgba"]
        m.mat_emission[:] = self._default["emission"]
        m.mat_rgba[self._sky, :3] = c.sky
        m.mat_emission[self._sky] = c.sky_glow
        m.mat_rgba[self._ground, :3] = c.ground
        if c.facades > 0 and len(self._facade):
            m.mat_rgba[self._facade, :3] = 1.0 - c.facades * self._season_shift(c.season)
        self.lamps_on = bool(c.lamps > 0 and self._floor_mat[1] >= 0)
        if self._floor_mat[1] >= 0:
            on = min(c.lamps, 1.0)
            m.mat_rgba[self._lamp_head, :3] = _LAMP_RGB * on
            m.mat_rgba[self._lamp_head, 3] = 1.0 if self.lamps_on else 0.0
            m.mat_emission[self._lamp_head] = c.lamps
            m.geom_matid[self._floor] = self._floor_mat[1] if self.lamps_on else self._floor_mat[0]
            m.mat_rgba[self._floor_mat[1], :3] = c.ground
            m.mat_emission[self._floor_mat[1]] = _POOL_EMISSION * c.lamps
        for cam in cameras:
            set_fog(cam, c)

    def place_heads(self, data: mujoco.MjData, camera_pose: NDArray[np.float64]) -> None:
        """Move the ``LAMP_HEADS`` lamp heads to the lamps nearest the camera at ``camera_pose``
        [x, y, yaw] among those ahead of it (or within 1.5 m); call before rendering."""
        if not self.lamps_on:
            return
        d = self._lamps - camera_pose[:2]
        dist = np.hypot(*d.T)
        ahead = d @ np.array([np.cos(camera_pose[2]), np.sin(camera_pose[2])]) > 0.3 * dist
        score = np.where(ahead | (dist < 1.5), dist, np.inf)
        near = np.argsort(score)[: len(self._heads)]
        pos = np.column_stack([self._lamps[near], np.full(len(near), LAMP_HEIGHT)])
        self.model.geom_pos[self._heads] = pos
        data.geom_xpos[self._heads] = pos  # world geoms: no kinematics needed

    def _season_shift(self, season: int) -> NDArray[np.float64]:
        if self._season is None or self._season[0] != season:
            rng = np.random.default_rng([self.city.seed, season, 17])
            self._season = (season, rng.uniform(0.0, 1.0, (len(self._facade), 3)))
        return self._season[1]


def paint_texture(model: mujoco.MjModel, name: str, image: NDArray[np.uint8]) -> None:
    """Write ``image`` into the model's texture ``name`` (before any renderer uploads it)."""
    tid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TEXTURE, name)
    a, h, w, c = model.tex_adr[tid], model.tex_height[tid], model.tex_width[tid], model.tex_nchannel[tid]
    model.tex_data[a : a + h * w * c] = image[:h, :w, :c].reshape(-1)


def set_fog(camera: Any, c: Conditions) -> None:
    """Turn the camera's fog on with ``c``'s distances and colour, or off.

    Raises
    ------
    ValueError
        If ``c`` has fog and the camera exposes no ``gl_targets()`` (a custom camera).
    """
    targets = camera.gl_targets() if hasattr(camera, "gl_targets") else None
    if targets is None:
        if c.has_fog:
            raise ValueError(f"camera {type(camera).__name__} has no gl_targets(): it cannot "
                             "render fog")
        return
    for scene, context in targets:
        scene.flags[mujoco.mjtRndFlag.mjRND_FOG] = int(c.has_fog)
        if c.has_fog:
            context.fogStart, context.fogEnd = c.fog
            context.fogRGBA[:] = (*c.fog_colour, 1.0)
