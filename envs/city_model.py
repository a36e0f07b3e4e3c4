"""The MuJoCo side of a :class:`~envs.scene.City` (a mixin): the MJCF document, the ground
and horizon textures painted into the compiled model, building and scenery geoms.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["GROUND_PIXELS", "HORIZON_HEIGHT", "HORIZON_PIXELS", "MAX_TEXTURE_SCALE",
           "CityModelMixin"]

GROUND_PIXELS = 1024  # floor texture side of the default 20 m city (4.7 cm a texel)
HORIZON_PIXELS = (512, 256)  # horizon wall texture (width, height) of the default city
#: the floor half-side the texture sizes above are for (the default 20 m city's)
_DEFAULT_FLOOR_HALF = 24.0
#: bigger cities get textures 2, 4 (at most) times as wide, so a texel stays <= 4.7 cm up to a
#: 164 m city (the 10 cm road markings and zebra stripes stay sharp); beyond, texels grow
MAX_TEXTURE_SCALE = 4
HORIZON_HEIGHT = 40.0  # m
#: contact attributes of the buildings and boundary walls: smooth (friction 0.1, about a plastic
#: bumper shell's on a painted wall; ``priority="1"`` so the wall's friction, not the wheels'
#: rubber 1.2, holds wherever the robot touches it). On rubber-friction walls a vehicle's shove
#: once wedged a wheel into the corner of a wall and the ground: the robot leant 19 degrees on
#: the building and stayed there whatever it was told, 350 steps to the episode's end (held-out
#: city 21, reset seed 3000034 of the robustness benchmark's traffic rows). On a smooth wall it
#: slides out. (Frictionless walls, ``condim="1"``, also free it, but the chassis then rocks on
#: a head-on bump and the bump sensor's force centroid jumps to one corner.)
SMOOTH_WALL = 'friction="0.1" priority="1"'
# horizon walls: distinct colours per side so heading is visible from far away
_HORIZON = {"E": (0.85, 0.55, 0.35), "N": (0.45, 0.6, 0.85), "W": (0.55, 0.8, 0.55), "S": (0.8, 0.75, 0.5)}


def _fmt(values: tuple[float, ...]) -> str:
    return " ".join(f"{v:.3f}" for v in values)


class CityModelMixin:
    """MJCF and textures of a city; uses its ``size``, ``street_width``, ``street_centers``,
    ``buildings`` and ``skyline``."""

    size: float
    seed: int
    half: float
    street_width: float
    street_centers: NDArray[np.float64]
    buildings: list[Any]
    skyline: list[Any]

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

    def texture_scale(self) -> int:
        """How many times the default city's texture widths this city's floor and horizon
        textures have: the smallest power of two (at most :data:`MAX_TEXTURE_SCALE`) keeping
        the default city's texel size, 1 for cities up to 20 m, 2 up to 68 m (a 60 m city's
        1024-pixel floor would have 8.6 cm texels and blur the road markings)."""
        ratio = self.floor_half() / _DEFAULT_FLOOR_HALF
        scale = 1
        while scale < ratio - 1e-9 and scale < MAX_TEXTURE_SCALE:
            scale *= 2
        return scale

    def ground_pixels(self) -> int:
        """Side (pixels) of the floor texture: :data:`GROUND_PIXELS` x :meth:`texture_scale`."""
        return GROUND_PIXELS * self.texture_scale()

    def horizon_pixels(self) -> tuple[int, int]:
        """(width, height) of each horizon wall texture (the width scales like the floor's)."""
        return HORIZON_PIXELS[0] * self.texture_scale(), HORIZON_PIXELS[1]

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

        paint("ground", self.ground_image(self.ground_pixels()))
        for side in "ENWS":  # MuJoCo maps the inner faces of the W and N walls mirrored
            image = self.horizon_image(side, *self.horizon_pixels())
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
                f'material="mat{i}" contype="2" conaffinity="2" {SMOOTH_WALL} group="2"/>'
            )
        for name, (x, y, hx, hy) in {  # invisible walls keep the robot in the city
            "E": (h + 0.25, 0, 0.25, h + 0.5), "W": (-h - 0.25, 0, 0.25, h + 0.5),
            "N": (0, h + 0.25, h + 0.5, 0.25), "S": (0, -h - 0.25, h + 0.5, 0.25),
        }.items():
            geoms.append(
                f'<geom name="wall{name}" type="box" pos="{x} {y} 0.5" size="{hx} {hy} 0.5" '
                f'rgba="1 1 1 0" contype="2" conaffinity="2" {SMOOTH_WALL} group="3"/>'
            )
        return assets, geoms

    def _scenery_xml(self, far: float) -> tuple[list[str], list[str]]:
        """Assets and visual-only geoms: floor and horizon walls (painted by :meth:`paint_textures`)."""
        f = far + 2.0
        ground, (sky_w, sky_h) = self.ground_pixels(), self.horizon_pixels()
        assets = [
            (f'<texture name="ground" type="2d" builtin="flat" width="{ground}" '
             f'height="{ground}" rgb1="0.3 0.3 0.3"/>'),
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
                f'<texture name="sky{name}" type="2d" builtin="flat" width="{sky_w}" '
                f'height="{sky_h}" rgb1="{_fmt(_HORIZON[name])}"/>'
            )
            assets.append(f'<material name="sky{name}" texture="sky{name}" texrepeat="1 1"/>')
            geoms.append(
                f'<geom name="horizon{name}" type="box" pos="{x} {y} {zc}" size="{hx} {hy} {zc}" '
                f'material="sky{name}" contype="0" conaffinity="0" group="2"/>'
            )
        return assets, geoms
