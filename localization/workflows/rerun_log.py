"""Rerun recordings: what the robot sees and believes, step by step, in the Rerun viewer.

Needs the ``viewer`` extra (``pip install "appearance-nav[viewer]"``, i.e. ``rerun-sdk``);
``appearance-nav track / eval / demo --rerun FILE.rrd`` write one, ``rerun FILE.rrd`` opens it.

:class:`RerunLog` writes one ``.rrd`` file. Entities (world frame, metres):

- ``map/world`` a static y-flip (Rerun's 2-D views point y down; the map is north up);
  under it ``city/buildings`` (static ``Boxes2D``, landmark towers labelled) and
  ``city/streets`` (static ``LineStrips2D``, the centrelines) over ``city/raster`` (the
  filled map of :mod:`localization.belief_render`, placed by a static transform);
- per run (``<run>`` e.g. ``track/representation_0`` or ``scripted/belief/episode_3``), under
  ``map/world/<run>``: ``true`` and ``belief`` (planar ``Transform3D``: translation
  ``[x, y, 0]`` and a rotation of yaw about z, each carrying a static robot arrow),
  ``ellipse`` (the belief's 2-sigma position ellipse), ``particles`` and ``hypotheses``
  (particle filter), ``path`` (the planned path), ``goal``;
- ``camera/<run>`` the camera image (JPEG);
- ``plots/<run>/{nis, nees, error, accepted}`` time series (``accepted`` is 1 when the
  measurement was accepted) and ``status/<run>`` a text log of the measurement and belief
  statuses when they change (and of kidnaps).

Timelines: ``step`` (the step within a run) and ``frame`` (one count over the whole file; a
run is cleared from the map when the next one starts). :class:`RerunRecorder` is a Gymnasium
wrapper that logs every step of a pose-wrapped env (``localization.wrappers``).
"""

from __future__ import annotations

import dataclasses
import io
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any, Self, SupportsFloat

import gymnasium as gym
import numpy as np
from numpy.typing import ArrayLike
from PIL import Image

from localization._validation import check_int
from localization.belief_render import (
    COLOURS,
    BeliefFrame,
    BeliefRenderer,
    CityMapLike,
    ellipse_polygon,
)

__all__ = ["VIEWER_EXTRA", "RerunLog", "RerunRecorder", "check_rrd_path", "require_rerun"]

VIEWER_EXTRA = 'pip install "appearance-nav[viewer]"'
ROBOT_ARROW = 0.5  # m


def require_rerun() -> ModuleType:
    """``import rerun``, or a ``ModuleNotFoundError`` that names the extra to install."""
    try:
        import rerun
    except ImportError as err:
        raise ModuleNotFoundError(f"Rerun recordings need rerun-sdk, which is not installed: "
                                  f"{VIEWER_EXTRA}") from err
    return rerun


def check_rrd_path(path: object, name: str = "path") -> Path:
    """``path`` as a Path to a writable ``.rrd`` file (its folder may not exist yet).

    Raises
    ------
    TypeError
        If ``path`` is not a str or os.PathLike.
    ValueError
        If it does not end in ``.rrd``, is a folder, or lies under a file.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name} must be a path to an .rrd file (str or os.PathLike), got "
                        f"{type(path).__name__}")
    p = Path(path)
    if p.suffix != ".rrd":
        raise ValueError(f"{name} must end in .rrd (a Rerun recording), got {str(path)!r}")
    if p.is_dir():
        raise ValueError(f"{name} {str(path)!r} is a folder; expected an .rrd file path")
    for parent in p.resolve().parents:
        if parent.exists():
            if not parent.is_dir():
                raise ValueError(f"{name} {str(path)!r}: {str(parent)!r} is a file, not a folder")
            break
    return p


class RerunLog:
    """One Rerun recording (``.rrd``) of runs on one city (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file to write (its folder is created).
    city_map : CityMapLike, optional
        The city (``env.unwrapped.top_down_map()``), logged as static geometry; or later
        with :meth:`log_city`.
    application_id : str
        Rerun's application id (the viewer groups recordings by it).
    max_particles : int
        At most this many particles are logged a step (the heaviest).
    jpeg_quality : int
        Camera images are stored as JPEG of this quality (1-100).
    """

    def __init__(self, path: str | Path, city_map: CityMapLike | None = None,
                 application_id: str = "appearance-nav", max_particles: int = 2000,
                 jpeg_quality: int = 90) -> None:
        self.path = check_rrd_path(path)
        self.max_particles = check_int(max_particles, "max_particles", low=0)
        self.jpeg_quality = check_int(jpeg_quality, "jpeg_quality", low=1, high=100)
        self.rr = require_rerun()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec = self.rr.RecordingStream(application_id)
        self.rec.set_log_time_enabled(False)  # our timelines only: step and frame
        self.rec.save(self.path, default_blueprint=self._blueprint())
        self.rec.log("map/world", self.rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        self.frame = 0
        self.run: str | None = None
        self._status: tuple[str, str] | None = None
        self.city_logged = False
        if city_map is not None:
            self.log_city(city_map)

    def _blueprint(self) -> Any:
        import rerun.blueprint as rrb

        return rrb.Blueprint(rrb.Horizontal(
            rrb.Spatial2DView(origin="map", name="city map"),
            rrb.Vertical(rrb.Spatial2DView(origin="camera", name="camera"),
                         rrb.TimeSeriesView(origin="plots", name="NIS, NEES, error"),
                         rrb.TextLogView(origin="status", name="status")),
            column_shares=[2, 1]))

    def log_city(self, city_map: CityMapLike) -> None:
        """The city's buildings and streets as static geometry under ``map/world/city``."""
        rr = self.rr
        fp = np.asarray(city_map.footprints, dtype=np.float64).reshape(-1, 4)
        colours = np.clip(255 * np.asarray(city_map.colours, dtype=np.float64), 0, 255)
        landmarks = np.asarray(city_map.landmarks, dtype=bool).reshape(-1)
        self.rec.log("map/world/city/buildings", rr.Boxes2D(
            mins=fp[:, :2], sizes=fp[:, 2:] - fp[:, :2], colors=colours.astype(np.uint8),
            labels=["landmark" if m else "" for m in landmarks], draw_order=10.0), static=True)
        c = np.asarray(city_map.street_centers, dtype=np.float64)
        lo, hi = float(c.min()), float(c.max())
        strips = [[[lo, y], [hi, y]] for y in c] + [[[x, lo], [x, hi]] for x in c]
        self.rec.log("map/world/city/streets", rr.LineStrips2D(
            strips, radii=0.03, colors=(250, 250, 250), draw_order=5.0), static=True)
        # the filled map of the videos underneath, pixel (c, r) at x = lo + c / s, y = hi - r / s
        raster = BeliefRenderer(city_map, panel=0)
        self.rec.log("map/world/city/raster", rr.Transform3D(
            translation=[raster.lo, raster.hi, 0.0],
            scale=[1.0 / raster.scale, -1.0 / raster.scale, 1.0]), static=True)
        png = io.BytesIO()
        Image.fromarray(raster.draw(BeliefFrame())).save(png, format="PNG")
        self.rec.log("map/world/city/raster", rr.EncodedImage(
            contents=png.getvalue(), media_type="image/png", draw_order=-10.0), static=True)
        self.city_logged = True

    # ------------------------------------------------------------------ steps
    def log_step(self, run: str, step: int, frame: BeliefFrame,
                 info: Mapping[str, Any] | None = None) -> None:
        """Log one step of ``run``: the frame's poses, ellipse, particles, path, goal and
        image, and ``info``'s NIS, NEES, statuses and kidnaps (all optional)."""
        if not isinstance(run, str) or not run.strip("/"):
            raise ValueError(f"run must be a non-empty entity path (str), got {run!r}")
        step = check_int(step, "step", low=0)
        if run != self.run:
            self.end_run()
            self.run = run
        rr, rec, info = self.rr, self.rec, info or {}
        rec.set_time("frame", sequence=self.frame)
        rec.set_time("step", sequence=step)
        self.frame += 1
        world = f"map/world/{run}"
        for name, pose in (("true", frame.true_pose), ("belief", frame.mean)):
            if pose is not None:
                self._pose(f"{world}/{name}", pose, COLOURS[name])
        if frame.mean is not None and frame.cov is not None:
            poly = ellipse_polygon(frame.mean, frame.cov)
            if len(poly):
                rec.log(f"{world}/ellipse", rr.LineStrips2D(
                    [np.vstack([poly, poly[:1]])], radii=0.03, colors=COLOURS["ellipse"],
                    draw_order=30.0))
        if frame.particles is not None:
            self._particles(f"{world}/particles", frame.particles, frame.weights)
        if frame.hypotheses is not None and len(frame.hypotheses):
            rec.log(f"{world}/hypotheses", rr.Points2D(
                np.asarray(frame.hypotheses)[:, :2], radii=0.12, colors=COLOURS["hypotheses"],
                draw_order=25.0))
        if frame.path is not None and len(frame.path) > 1:
            rec.log(f"{world}/path", rr.LineStrips2D([np.asarray(frame.path)], radii=0.04,
                                                     colors=COLOURS["path"], draw_order=15.0))
        if frame.goal is not None:
            rec.log(f"{world}/goal", rr.Points2D([np.asarray(frame.goal)[:2]], radii=0.3,
                                                 colors=COLOURS["goal"], draw_order=16.0))
        if frame.image is not None:
            rec.log(f"camera/{run}", rr.Image(np.asarray(frame.image, dtype=np.uint8))
                    .compress(jpeg_quality=self.jpeg_quality))
        self._series(run, frame, info)

    def _pose(self, entity: str, pose: ArrayLike, colour: tuple[int, int, int]) -> None:
        x, y, yaw = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
        if not np.all(np.isfinite([x, y, yaw])):
            return
        rr = self.rr
        self.rec.log(entity, rr.Transform3D(
            translation=[x, y, 0.0], rotation=rr.RotationAxisAngle(axis=[0, 0, 1], radians=yaw)))
        # the robot in its own frame; logged with the pose (not static) so clearing a run
        # clears it too
        self.rec.log(f"{entity}/robot", rr.Arrows2D(
            origins=[[-0.5 * ROBOT_ARROW, 0.0]], vectors=[[ROBOT_ARROW, 0.0]], radii=0.06,
            colors=colour, draw_order=40.0))

    def _particles(self, entity: str, particles: ArrayLike, weights: ArrayLike | None) -> None:
        X = np.asarray(particles, dtype=np.float64).reshape(-1, 3)
        if len(X) > self.max_particles:
            order = (np.argsort(np.asarray(weights, dtype=np.float64))[::-1] if weights is not None
                     else np.arange(len(X)))
            X = X[order[: self.max_particles]]
        self.rec.log(entity, self.rr.Points2D(X[:, :2], radii=0.04, colors=COLOURS["particles"],
                                              draw_order=20.0))

    def _series(self, run: str, frame: BeliefFrame, info: Mapping[str, Any]) -> None:
        rr, rec = self.rr, self.rec
        values = {"nis": info.get("nis"), "nees": info.get("nees")}
        if frame.true_pose is not None and frame.mean is not None:
            d = np.asarray(frame.true_pose)[:2] - np.asarray(frame.mean)[:2]
            values["error"] = float(np.hypot(*d))
        if "measurement_status" in info:
            values["accepted"] = float(info["measurement_status"] == "accepted")
        for name, value in values.items():
            if value is not None and np.isfinite(value):
                rec.log(f"plots/{run}/{name}", rr.Scalars(float(value)))
        status = (str(info.get("measurement_status", "")), str(info.get("belief_status", "")))
        if any(status) and status != self._status:
            rec.log(f"status/{run}", rr.TextLog(f"measurement: {status[0]}, belief: {status[1]}",
                                                level="INFO"))
            self._status = status
        if info.get("kidnapped"):
            rec.log(f"status/{run}", rr.TextLog("kidnapped", level="WARN"))

    def end_run(self) -> None:
        """Clear the current run from the map (on the ``frame`` timeline)."""
        if self.run is not None:
            self.rec.reset_time()  # on the frame timeline only: the run stays on "step"
            self.rec.set_time("frame", sequence=self.frame)
            self.rec.log(f"map/world/{self.run}", self.rr.Clear(recursive=True))
            self.rec.log(f"camera/{self.run}", self.rr.Clear(recursive=True))
            self.run, self._status = None, None

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if self.rec is not None:
            self.end_run()
            self.rec.flush()
            self.rec.disconnect()
            self.rec = None  # type: ignore[assignment]

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class RerunRecorder(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Log every step of a pose-wrapped env to a :class:`RerunLog` (a Gymnasium wrapper).

    Parameters
    ----------
    env : gymnasium.Env
        A pose wrapper of :mod:`localization.wrappers` (or an env wrapping one): it has
        ``render_frame()``.
    log : RerunLog
        Where the steps go (the city is logged on the first reset if it was not).
    name : str
        The runs' entity path; episode k is the run ``<name>/episode_<k>``.
    episodes : int or None
        Record only the first this many episodes (then the wrapper only passes through).
    path : callable, optional
        Returns the planned path (p, 2) or None each step (e.g. ``lambda: agent.path``);
        default: the pose wrapper's ``planned_path``.
    """

    def __init__(self, env: gym.Env, log: RerunLog, name: str, episodes: int | None = None,
                 path: Callable[[], ArrayLike | None] | None = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, name=name, episodes=episodes)
        gym.Wrapper.__init__(self, env)
        if not isinstance(log, RerunLog):
            raise TypeError(f"log must be a RerunLog, got {type(log).__name__}")
        try:
            self._frame = env.get_wrapper_attr("render_frame")
        except AttributeError:
            raise TypeError("env must be wrapped in a pose wrapper of localization.wrappers "
                            "(BeliefWrapper, OracleWrapper or DeadReckoningWrapper): it has no "
                            "render_frame()") from None
        if not isinstance(name, str) or not name.strip("/"):
            raise ValueError(f"name must be a non-empty entity path (str), got {name!r}")
        self.episodes = None if episodes is None else check_int(episodes, "episodes", low=0)
        self.log, self.name, self.path = log, name.strip("/"), path
        self.episode, self.step_count = -1, 0

    @property
    def recording(self) -> bool:
        """Whether the current episode is being recorded."""
        return 0 <= self.episode and (self.episodes is None or self.episode < self.episodes)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self.episode += 1
        self.step_count = 0
        if self.recording:
            if not self.log.city_logged:
                self.log.log_city(self.env.unwrapped.top_down_map())
            self._log(info)
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.step_count += 1
        if self.recording:
            self._log(info)
        return obs, reward, terminated, truncated, info

    def _log(self, info: dict[str, Any]) -> None:
        frame = self._frame()
        if self.path is not None:
            path = self.path()
            frame = dataclasses.replace(frame, path=None if path is None else np.asarray(path))
        self.log.log_step(f"{self.name}/episode_{self.episode}", self.step_count, frame, info)
