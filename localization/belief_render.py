"""Draw what the robot believes on the city map: the frames of ``render()`` and of videos.

:class:`BeliefRenderer` draws one :class:`BeliefFrame` (the belief mean and its 2-sigma
position ellipse, the particles and the other hypotheses, the true pose, the goal, the
planned path and the camera image) on a top-down map of the city, north up:

    +--------------------------+-----------+
    |                          |  camera   |
    |   map (pixels x pixels)  |  image    |
    |                          +-----------+
    |                          |  status   |
    |                          |  legend   |
    +--------------------------+-----------+

The map's buildings and streets are rasterised once with numpy (from any object with the
attributes of :class:`CityMapLike`, e.g. ``env.unwrapped.top_down_map()``); each frame
copies that raster and draws on it with Pillow's ``ImageDraw`` (aliased, so every colour of
:data:`COLOURS` lands exactly). About 1 ms a frame at the default size
(``appearance-nav bench --only env`` measures it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image, ImageDraw, ImageFont

from localization._validation import check_int
from localization.geometry import Array

__all__ = ["COLOURS", "BeliefFrame", "BeliefRenderer", "CityMapLike", "ellipse_polygon"]

#: RGB colours of what a frame shows (tests look for them)
COLOURS: dict[str, tuple[int, int, int]] = {
    "ground": (214, 210, 200), "street": (150, 150, 156), "outside": (120, 135, 110),
    "true": (20, 20, 20), "belief": (0, 90, 255), "ellipse": (0, 170, 255),
    "particles": (190, 40, 200), "hypotheses": (255, 60, 160), "goal": (0, 190, 70),
    "path": (255, 150, 0), "panel": (32, 32, 36), "text": (235, 235, 235),
}
ROBOT_LENGTH = 0.55  # m, the drawn pose arrows
GOAL_RADIUS = 0.3  # m
LEGEND = (("true", "true pose"), ("belief", "belief + 2-sigma"), ("particles", "particles"),
          ("hypotheses", "other hypotheses"), ("path", "planned path"), ("goal", "goal"))


class CityMapLike(Protocol):
    """What the renderer reads from a city map (``envs.top_down.TopDownMap`` has it)."""

    bounds: tuple[float, float]
    footprints: NDArray[np.float64]  # (n, 4) [xmin, ymin, xmax, ymax]
    colours: NDArray[np.float64]  # (n, 3) in [0, 1]
    landmarks: NDArray[np.bool_]  # (n,)
    street_centers: NDArray[np.float64]  # (k,)
    street_width: float


@dataclass(frozen=True)
class BeliefFrame:
    """What one frame shows; every field is optional (None: not drawn).

    Attributes
    ----------
    mean : (3,) belief mean [x, y, yaw].
    cov : (3, 3) belief covariance (its (x, y) block gives the 2-sigma ellipse).
    true_pose : (3,) the true pose (evaluation only).
    goal : (2,) goal position.
    particles : (N, 3) particle poses.
    weights : (N,) particle weights (the heaviest are drawn when there are too many).
    hypotheses : (k, 3) means of the hypotheses other than ``mean``'s.
    path : (p, 2) the planned path.
    image : (H, W, 3) uint8 camera image.
    lines : status text, one string a line.
    """

    mean: Array | None = None
    cov: Array | None = None
    true_pose: Array | None = None
    goal: Array | None = None
    particles: Array | None = None
    weights: Array | None = None
    hypotheses: Array | None = None
    path: Array | None = None
    image: NDArray[np.uint8] | None = None
    lines: tuple[str, ...] = ()


def ellipse_polygon(mean: ArrayLike, cov: ArrayLike, n_sigma: float = 2.0,
                    n: int = 64) -> Array:
    """The ``n_sigma`` ellipse of a 2-D Gaussian as an (n, 2) polygon (world frame).

    ``cov`` may be the (3, 3) pose covariance: its (x, y) block is used. A covariance that
    is not finite gives an empty (0, 2) polygon (nothing to draw).
    """
    c = np.asarray(cov, dtype=np.float64)[:2, :2]
    m = np.asarray(mean, dtype=np.float64)[:2]
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(m))):
        return np.zeros((0, 2))
    vals, vecs = np.linalg.eigh(0.5 * (c + c.T))
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1)
    return m + n_sigma * (circle * np.sqrt(np.maximum(vals, 0.0))) @ vecs.T


class BeliefRenderer:
    """Draw :class:`BeliefFrame` s on a city map (see the module docstring).

    Parameters
    ----------
    city_map : CityMapLike
        The city from above (``env.unwrapped.top_down_map()``).
    pixels : int
        Side of the square map (the frame is ``(pixels, pixels + panel, 3)``).
    panel : int
        Width of the side panel (camera image, status, legend); 0 for the map alone.
    max_particles : int
        At most this many particles are drawn (the heaviest).
    """

    def __init__(self, city_map: CityMapLike, pixels: int = 384, panel: int = 192,
                 max_particles: int = 4000) -> None:
        self.pixels = check_int(pixels, "pixels", low=32, high=4096)
        self.panel = check_int(panel, "panel", low=0, high=4096)
        self.max_particles = check_int(max_particles, "max_particles", low=0)
        lo, hi = (float(v) for v in city_map.bounds)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise ValueError(f"city_map.bounds must be finite (lo, hi) with hi > lo, got "
                             f"{city_map.bounds}")
        self.lo, self.hi = lo, hi
        self.scale = self.pixels / (hi - lo)  # pixels per metre
        self._font = ImageFont.load_default()
        self._base = self._background(city_map)
        if self.panel:
            self._legend(self._base)

    @property
    def shape(self) -> tuple[int, int, int]:
        """The frame's shape ``(pixels, pixels + panel, 3)``."""
        return self.pixels, self.pixels + self.panel, 3

    def to_pixels(self, xy: ArrayLike) -> Array:
        """World (n, 2) -> pixel (n, 2) coordinates ``(column, row)``, row 0 north."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.stack([(p[:, 0] - self.lo) * self.scale, (self.hi - p[:, 1]) * self.scale],
                        axis=1)

    # ------------------------------------------------------------------ the map
    def _background(self, city_map: CityMapLike) -> NDArray[np.uint8]:
        n = self.pixels
        ticks = self.lo + (np.arange(n) + 0.5) / self.scale
        x, y = ticks[None, :], ticks[::-1, None]  # row 0 is north
        img = np.empty((n, n + self.panel, 3), np.uint8)
        img[:] = COLOURS["panel"]
        view = img[:, :n]
        view[:] = COLOURS["ground"]
        c = np.asarray(city_map.street_centers, dtype=np.float64).reshape(-1)
        if c.size:
            hw = 0.5 * float(city_map.street_width)
            street = (np.abs(x[..., None] - c).min(-1) <= hw) | (np.abs(y[..., None] - c).min(-1)
                                                                 <= hw)
            view[street] = COLOURS["street"]
        fp = np.asarray(city_map.footprints, dtype=np.float64).reshape(-1, 4)
        rgb = np.asarray(city_map.colours, dtype=np.float64).reshape(-1, 3)
        landmark = np.asarray(city_map.landmarks, dtype=bool).reshape(-1)
        for (x0, y0, x1, y1), colour, special in zip(fp, rgb, landmark, strict=True):
            inside = (x0 <= x) & (x <= x1) & (y0 <= y) & (y <= y1)
            muted = colour if special else 0.45 * colour + 0.55 * 0.55  # overlays stand out
            view[inside] = np.clip(255 * muted, 0, 255).astype(np.uint8)
        return img

    # ------------------------------------------------------------------ a frame
    def draw(self, frame: BeliefFrame) -> NDArray[np.uint8]:
        """The frame ``(pixels, pixels + panel, 3)`` uint8 showing ``frame``."""
        img = self._base.copy()
        if frame.particles is not None:
            self._particles(img, frame.particles, frame.weights)
        canvas = Image.fromarray(img)
        draw = ImageDraw.Draw(canvas)
        if frame.path is not None and len(frame.path) > 1:
            draw.line([tuple(p) for p in self.to_pixels(frame.path)], fill=COLOURS["path"],
                      width=2)
        if frame.goal is not None:
            self._disc(draw, frame.goal, GOAL_RADIUS, COLOURS["goal"])
        if frame.hypotheses is not None:
            for h in np.asarray(frame.hypotheses, dtype=np.float64).reshape(-1, 3):
                self._arrow(draw, h, COLOURS["hypotheses"], outline=None)
        if frame.mean is not None and frame.cov is not None:
            poly = self.to_pixels(ellipse_polygon(frame.mean, frame.cov))
            if len(poly):
                draw.line([tuple(p) for p in np.vstack([poly, poly[:1]])],
                          fill=COLOURS["ellipse"], width=2)
        if frame.mean is not None:
            self._arrow(draw, frame.mean, COLOURS["belief"], outline=(255, 255, 255))
        if frame.true_pose is not None:  # an outline on top: the belief shows through it
            self._arrow(draw, frame.true_pose, None, outline=COLOURS["true"], width=2)
        if self.panel:
            self._panel(canvas, draw, frame)
        return np.asarray(canvas)

    def _particles(self, img: NDArray[np.uint8], particles: ArrayLike,
                   weights: ArrayLike | None) -> None:
        X = np.asarray(particles, dtype=np.float64).reshape(-1, 3)
        if weights is not None and len(X) > self.max_particles:
            X = X[np.argsort(np.asarray(weights, dtype=np.float64))[::-1][:self.max_particles]]
        X = X[: self.max_particles]
        px = np.floor(self.to_pixels(X[:, :2])).astype(np.int64)
        ok = np.all((px >= 0) & (px < self.pixels - 1), axis=1)
        col, row = px[ok, 0], px[ok, 1]
        for dr, dc in ((0, 0), (0, 1), (1, 0), (1, 1)):  # 2 x 2 dots
            img[row + dr, col + dc] = COLOURS["particles"]

    def _disc(self, draw: ImageDraw.ImageDraw, xy: ArrayLike, radius: float,
              fill: tuple[int, int, int]) -> None:
        (c, r), = self.to_pixels(np.asarray(xy, dtype=np.float64)[:2])
        s = max(radius * self.scale, 3.0)
        draw.ellipse([c - s, r - s, c + s, r + s], fill=fill, outline=(255, 255, 255))

    def _arrow(self, draw: ImageDraw.ImageDraw, pose: ArrayLike,
               fill: tuple[int, int, int] | None, outline: tuple[int, int, int] | None,
               width: int = 1) -> None:
        """A pose as a triangle pointing along its heading."""
        x, y, yaw = np.asarray(pose, dtype=np.float64)[:3]
        if not np.all(np.isfinite([x, y, yaw])):
            return
        length = max(ROBOT_LENGTH, 10.0 / self.scale)
        body = np.array([[0.6, 0.0], [-0.4, 0.35], [-0.25, 0.0], [-0.4, -0.35]]) * length
        c, s = np.cos(yaw), np.sin(yaw)
        world = body @ np.array([[c, s], [-s, c]]) + [x, y]
        draw.polygon([tuple(p) for p in self.to_pixels(world)], fill=fill, outline=outline,
                     width=width)

    def _panel(self, canvas: Image.Image, draw: ImageDraw.ImageDraw, frame: BeliefFrame) -> None:
        x0, top = self.pixels, 0
        if frame.image is not None:
            cam = Image.fromarray(np.asarray(frame.image, dtype=np.uint8))
            h = max(1, round(cam.height * self.panel / cam.width))
            canvas.paste(cam.resize((self.panel, h), Image.Resampling.NEAREST), (x0, 0))
            top = h
        y = top + 4
        for line in frame.lines:
            draw.text((x0 + 4, y), line, fill=COLOURS["text"], font=self._font)
            y += 13

    def _legend(self, img: NDArray[np.uint8]) -> None:
        """The legend at the bottom of the panel (drawn once, into the background)."""
        canvas = Image.fromarray(img)
        draw = ImageDraw.Draw(canvas)
        x0, y = self.pixels, self.pixels - 13 * len(LEGEND) - 2
        for name, label in LEGEND:
            draw.rectangle([x0 + 4, y + 2, x0 + 12, y + 10], fill=COLOURS[name])
            draw.text((x0 + 16, y), label, fill=COLOURS["text"], font=self._font)
            y += 13
        img[:] = np.asarray(canvas)
