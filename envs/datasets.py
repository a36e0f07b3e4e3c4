"""Image/pose datasets from the city: collect, save, load.

``collect_dataset(env, n, mode, seed)`` returns ``images`` (n, H, W, 3) uint8 and the
true ``poses`` (n, 3) float64 ``[x, y, yaw]``:

- ``"grid"``: a regular grid of street positions times ``n_headings`` headings (the
  grid spacing is the largest giving at least n poses; n of them are taken evenly);
- ``"random"``: uniform random free poses;
- ``"route"``: the robot drives (physics, the env's motion noise) around
  ``city.route()`` with a pure-pursuit controller; one sample per env step;
- ``"lanes"``: poses around the driving lanes of the street graph (``envs.lanes``: every
  street in both directions and every turn, or only the route's), each reached *driving*:
  the robot is placed ``ROLL_STEPS`` steps before the pose at cruise speed and drives
  there, so the camera has the pitch and roll of a moving robot (a teleported robot
  stands level; a driving one pitches ~1 degree, which shifted a localizer trained on
  level images by ~0.1 m along track);
- ``"coverage"``: poses over the whole street surface at every heading
  (:func:`envs.coverage.coverage_poses`: off the lanes too, intersections weighted up,
  stratified headings), each reached driving like "lanes" but with a random control of an
  off-lane drive (forward speed up to cruise speed, any turn rate, turning on the spot
  included).

For "grid" and "random" the robot is teleported (``mj_forward``) and the camera
rendered, which is fast.

:func:`drive_route` records a drive around the route with its controls (for the process
noise and the measurement noise of a filter), :func:`drive_streets` one along a random tour
of all the streets, :func:`drive_off_lane` one that leaves the lanes (:mod:`envs.off_lane`).

:func:`save_dataset` / :func:`load_dataset` (the ``.npz`` format) are defined in
:mod:`localization.recorded`, next to the readers of recorded image folders, and re-exported
here.
"""

from __future__ import annotations

from itertools import pairwise
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from envs.coverage import coverage_poses
from envs.driving import bearing, pursuit_turn_rate
from envs.lanes import lane_poses, street_tour
from envs.motion_model import wrap_angle
from envs.off_lane import OffLanePilot, off_lane_waypoints
from envs.robot import HALF_TRACK, ROBOT_RADIUS, WHEEL_RADIUS
from localization._validation import (
    check_bool,
    check_choice,
    check_int,
    check_options,
    check_real,
    check_seed,
)
from localization.recorded import load_dataset, save_dataset  # the .npz format, one definition

__all__ = ["MODES", "PurePursuit", "collect_dataset", "drive_off_lane", "drive_route",
           "drive_streets", "grid_poses", "load_dataset", "save_dataset", "slice_seed"]

MODES = ("grid", "random", "route", "lanes", "coverage")
#: the keyword arguments of :func:`envs.lanes.lane_poses` that ``collect_dataset`` passes on
LANE_OPTIONS = ("lanes", "lateral", "heading", "turn_radius", "turn_weight")
#: the keyword arguments of :func:`envs.coverage.coverage_poses` that it passes on
COVERAGE_OPTIONS = ("region", "corner_weight", "corner_reach", "margin")
POSE_MARGIN = ROBOT_RADIUS + 0.1  # m of clearance to buildings for teleported poses
ROLL_STEPS = 3  # env steps driven into each "lanes" pose
CRUISE_SPEED = 0.6  # m/s, PurePursuit's default speed


def grid_poses(city: Any, n: int, n_headings: int = 8, margin: float = POSE_MARGIN) -> NDArray[np.float64]:
    """Return n poses (n, 3) from a regular grid of free positions x ``n_headings`` headings."""
    n = check_int(n, "n", low=1)
    n_headings = check_int(n_headings, "n_headings", low=1)
    margin = check_real(margin, "margin", low=0.0)
    headings = wrap_angle(np.linspace(-np.pi, np.pi, n_headings, endpoint=False) + np.pi / n_headings)

    def positions(spacing: float) -> NDArray[np.float64]:
        ticks = np.arange(-city.half + spacing / 2, city.half, spacing)
        xy = np.stack(np.meshgrid(ticks, ticks), axis=-1).reshape(-1, 2)
        return xy[city.free_mask(xy, margin)]

    need = int(np.ceil(n / n_headings))
    lo, hi = 1e-3, city.size
    for _ in range(40):  # largest spacing with enough free grid points
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if len(positions(mid)) >= need else (lo, mid)
    xy = positions(lo)
    poses = np.concatenate([np.repeat(xy, len(headings), axis=0), np.tile(headings, len(xy))[:, None]], axis=1)
    idx = np.round(np.linspace(0, len(poses) - 1, n)).astype(int)
    return poses[idx]


class PurePursuit:
    """Pure-pursuit steering along a polyline, like a car following a lane.

    Parameters
    ----------
    waypoints : (p, 2) polyline; a closed loop (the last point connects back to the first)
        unless ``closed=False``.
    lookahead : float — distance (m) to the carrot point along the path.
    speed : float — forward speed command (m/s).
    w_max : float — bound on the angular velocity command (rad/s).
    step : float — path resampling step (m).
    closed : bool — the path loops; an open path ends at its last waypoint (the carrot
        stays there).
    """

    def __init__(self, waypoints: NDArray[np.float64], lookahead: float = 0.8, speed: float = 0.6,
                 w_max: float = 1.0, step: float = 0.05, closed: bool = True) -> None:
        waypoints = np.asarray(waypoints, dtype=np.float64)
        loop = np.vstack([waypoints, waypoints[:1]]) if closed else waypoints
        pts = [a + (b - a) * t for a, b in pairwise(loop)
               for t in np.arange(0, 1, step / max(np.hypot(*(b - a)), 1e-9))]
        self.path = np.array(pts if closed else [*pts, loop[-1]])
        self.lookahead, self.speed, self.w_max, self.step = lookahead, speed, w_max, step
        self.closed = closed
        self.index = 0

    def _at(self, index: NDArray[np.int_] | int) -> NDArray[np.int_] | int:
        n = len(self.path)
        return np.mod(index, n) if self.closed else np.minimum(index, n - 1)

    def start_pose(self, index: int = 0) -> NDArray[np.float64]:
        """Path point ``index`` (default the first), heading along the path, (3,); the
        controller continues from there."""
        index = int(self._at(int(index)))
        self.index = index
        ahead = int(self._at(index + 1))
        d = self.path[ahead] - self.path[index] if ahead != index else \
            self.path[index] - self.path[index - 1]  # the end of an open path
        return np.array([*self.path[index], np.arctan2(d[1], d[0])])

    def __call__(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return the control U = [v, w] for the current pose."""
        window = self._at(self.index + np.arange(40))  # search only ahead: the loop crosses itself
        d = np.hypot(*(self.path[window] - pose[:2]).T)
        self.index = int(window[np.argmin(d)])
        carrot = self.path[self._at(self.index + int(self.lookahead / self.step))]
        alpha = bearing(pose, carrot)
        w = pursuit_turn_rate(alpha, self.speed, self.lookahead, self.w_max)
        v = self.speed * max(0.3, np.cos(alpha))  # slow down in sharp turns
        return np.array([v, w])


def _drive_into(base: Any, pose: NDArray[np.float64], curvature: float, steps: int,
                placed: Any = None) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """Place the robot ``steps`` env steps back along an arc of ``curvature`` at cruise speed
    (body and wheels moving), drive ``[v, v * curvature]`` into ``pose``; image and true pose.
    ``placed()`` (optional) runs once the robot is at its start (a new look, its traffic
    spawned away from the robot there)."""
    return _drive_in(base, pose, CRUISE_SPEED, CRUISE_SPEED * curvature, steps, placed)


def _drive_in(base: Any, pose: NDArray[np.float64], v: float, w: float, steps: int,
              placed: Any = None) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """:func:`_drive_into` with the control ``[v, w]`` (``v = 0``: turning on the spot)."""
    back = steps * base.dt
    yaw0 = pose[2] - w * back
    if abs(w) > 1e-9:
        start = pose[:2] - v / w * np.array([np.sin(pose[2]) - np.sin(yaw0),
                                             np.cos(yaw0) - np.cos(pose[2])])
    else:
        start = pose[:2] - v * back * np.array([np.cos(yaw0), np.sin(yaw0)])
    base.set_pose([start[0], start[1], yaw0])
    if placed is not None:
        placed()
    m, d = base.model, base.data
    root = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "root")]
    d.qvel[root:root + 3] = [v * np.cos(yaw0), v * np.sin(yaw0), 0.0]
    d.qvel[root + 5] = w
    for name, side in (("left", -1.0), ("right", 1.0)):
        dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]
        d.qvel[dof] = (v + side * w * HALF_TRACK) / WHEEL_RADIUS
    mujoco.mj_forward(m, d)
    for _ in range(steps):
        obs, _, _, _, info = base.step(np.array([v, w]))
    return obs["image"], info["pose"]


def check_city_env(env: object, name: str = "env") -> Any:
    """``env.unwrapped`` if ``env`` is an AppearanceNav env (wrapped or not), else ``TypeError``."""
    base = getattr(env, "unwrapped", None)
    if not (hasattr(base, "city") and hasattr(base, "render_camera")):
        raise TypeError(f"{name} must be an AppearanceNav env (gymnasium.make('AppearanceNav-v0')), "
                        f"got {type(env).__name__}")
    return base


def collect_dataset(env: gym.Env, n: int, mode: str = "random", seed: int = 0, n_headings: int = 8,
                    progress: bool = True, start: int = 0, stop: int | None = None,
                    **lane_options: Any,
                    ) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """Collect n camera images with their true poses.

    Parameters
    ----------
    env : an AppearanceNav env (wrapped or not).
    n : int — number of samples.
    mode : "grid", "random", "route" or "lanes" (see the module docstring).
    seed : int — seeds the random poses / the env reset for "route" and "lanes".
    n_headings : int — headings per grid position ("grid" only).
    progress : bool — show a tqdm progress bar.
    start, stop : int — collect only samples ``start .. stop - 1`` (default all n) of the
        n-sample dataset ("grid", "random", "lanes", "coverage"; "route" is one drive: all
        of it). The poses are those of the whole dataset. The per-sample randomness (the
        looks of randomised conditions, the motion noise of the drive-in) restarts at
        ``start`` from the env reset with :func:`slice_seed` ``(seed, start)``. Slices of
        "grid" and "random" without that randomness equal the whole run's exactly; "lanes"
        slices equal it in the images and within rounding (~1e-15) in the poses (the wheels'
        joint angles carry over from drive to drive). The same slices always give the same
        samples (``appearance-nav collect --workers`` collects in fixed slices).
    **lane_options : keyword arguments of :func:`envs.lanes.lane_poses` ("lanes" only):
        ``lanes`` ("streets" or "route"), ``lateral``, ``heading``, ``turn_radius``,
        ``turn_weight``; or of :func:`envs.coverage.coverage_poses` ("coverage" only):
        ``region`` ("streets" or "free"), ``corner_weight``, ``corner_reach``, ``margin``
        (clearance to buildings, m: at least the robot's radius ``ROBOT_RADIUS``; default
        ``POSE_MARGIN``). The poses
        returned are the true poses reached (within a few mm of the sampled ones).

    The env's state is changed (a reset seeded from ``seed``, then teleports, or a drive for
    "route"): reset it before running episodes on it. The reset also applies the look of an
    env made with conditions (a fresh env would otherwise show today's). On an env made
    with randomised conditions (``conditions="random"``) every sample but those of "route"
    (one drive, one look) gets its own look (``env.set_conditions()``), so the dataset covers
    the randomisation.

    Returns
    -------
    images : (n, H, W, 3) uint8
    poses : (n, 3) float64 ``[x, y, yaw]``
    """
    base = check_city_env(env)
    n = check_int(n, "n", low=1)
    check_choice(mode, "mode", MODES)
    seed = check_seed(seed, "seed")
    n_headings = check_int(n_headings, "n_headings", low=1)
    check_bool(progress, "progress")
    if mode == "coverage":
        check_options(lane_options, "coverage option", COVERAGE_OPTIONS)
        if "margin" in lane_options:
            check_real(lane_options["margin"], "margin", low=ROBOT_RADIUS)
    else:
        check_options(lane_options, "lane option", LANE_OPTIONS)
    if lane_options and mode not in ("lanes", "coverage"):
        raise ValueError(f"lane options {sorted(lane_options)} apply to mode 'lanes' only")
    start, stop = _check_slice(start, stop, n, mode)
    stream = slice_seed(seed, start)
    city = base.city
    images = np.empty((stop - start, *base.image_size, 3), np.uint8)
    poses = np.empty((stop - start, 3))
    bar = tqdm(total=stop - start, desc=f"collect {mode}", disable=not progress, leave=False)
    vary = bool(getattr(base, "randomised_conditions", False))
    redraw = base.set_conditions if vary else (lambda: None)
    # one seeded reset before teleporting: it applies the env's look (a fresh env shows
    # today's light until reset) and seeds the looks and the drive-ins' motion noise
    if mode != "route":
        base.reset(seed=stream)
    if mode == "route":
        pilot = PurePursuit(city.route(), w_max=base.W_MAX)
        obs, info = base.reset(seed=seed, options={"pose": pilot.start_pose()})
        pose = info["pose"]
        for i in range(n):
            obs, _, _, _, info = base.step(pilot(pose))
            pose = info["pose"]
            images[i], poses[i] = obs["image"], pose
            bar.update()
    elif mode == "lanes":
        targets, curvature = lane_poses(city, n, np.random.default_rng(seed),
                                        margin=POSE_MARGIN, **lane_options)
        for i, (target, k) in enumerate(zip(targets[start:stop], curvature[start:stop])):
            images[i], poses[i] = _drive_into(base, target, k, ROLL_STEPS, redraw)
            bar.update()
    elif mode == "coverage":
        rng = np.random.default_rng(seed)
        targets = coverage_poses(city, n, rng, **{"margin": POSE_MARGIN, **lane_options})
        controls = np.column_stack([rng.uniform(0.0, CRUISE_SPEED, n),
                                    rng.uniform(-base.W_MAX, base.W_MAX, n)])
        for i, (target, (v, w)) in enumerate(zip(targets[start:stop], controls[start:stop])):
            images[i], poses[i] = _drive_in(base, target, v, w, ROLL_STEPS, redraw)
            bar.update()
    else:
        if mode == "grid":
            targets = grid_poses(city, n, n_headings)
        else:
            rng = np.random.default_rng(seed)
            targets = np.array([city.random_free_pose(rng, POSE_MARGIN) for _ in range(stop)])
        for i, target in enumerate(targets[start:stop]):
            base.set_pose(target)
            redraw()
            images[i], poses[i] = base.render_camera(), base.pose
            bar.update()
    bar.close()
    return images, poses


def slice_seed(seed: int, start: int) -> int:
    """The env reset seed of the samples from ``start`` on in :func:`collect_dataset`:
    ``seed`` itself at 0 (the whole run), else one drawn from ``SeedSequence([seed, start])``."""
    if start == 0:
        return seed
    return int(np.random.SeedSequence([seed, start]).generate_state(1, np.uint32)[0])


def _check_slice(start: object, stop: object, n: int, mode: str) -> tuple[int, int]:
    """``(start, stop)`` as ints with ``0 <= start < stop <= n`` (stop None: n)."""
    start = check_int(start, "start", low=0)
    stop = n if stop is None else check_int(stop, "stop", low=1)
    if not start < stop <= n:
        raise ValueError(f"start, stop must satisfy 0 <= start < stop <= n = {n}, "
                         f"got start={start}, stop={stop}")
    if mode == "route" and (start, stop) != (0, n):
        raise ValueError("mode 'route' is one continuous drive: start and stop must be 0 and n")
    return start, stop


def drive_route(env: gym.Env, n: int, seed: int = 0, start: int = 0, progress: bool = True,
                ) -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.float64]]:
    """Drive n steps around ``city.route()`` with :class:`PurePursuit` on the true pose.

    Parameters
    ----------
    env : an AppearanceNav env (wrapped or not); it is reset with ``seed``.
    n : int — number of steps.
    seed : int — the env reset (motion noise).
    start : int — index of the path point to start from (``PurePursuit.path``).
    progress : bool

    Returns
    -------
    images : (n + 1, H, W, 3) uint8 — frame 0 is the reset image.
    poses : (n + 1, 3) float64 — true poses.
    controls : (n, 2) float64 — the commanded controls (controls[t] moves poses[t] to poses[t+1]).
    """
    base = check_city_env(env)
    _check_drive(n, seed, progress)
    start = check_int(start, "start")
    pilot = PurePursuit(base.city.route(), w_max=base.W_MAX)
    return _drive(env, pilot, pilot.start_pose(start), n, seed, progress, "drive route")


def drive_streets(env: gym.Env, n: int, seed: int = 0, speed: float = CRUISE_SPEED,
                  progress: bool = True,
                  ) -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.float64]]:
    """Drive n steps along a random tour of the streets (:func:`envs.lanes.street_tour`: every
    street both ways, every turn) with :class:`PurePursuit` on the true pose.

    The tour (drawn from ``seed``) starts at an intersection, heading along its first street,
    and is long enough for n steps at ``speed``. Arguments and returns as :func:`drive_route`.
    """
    base = check_city_env(env)
    _check_drive(n, seed, progress)
    speed = check_real(speed, "speed", low=0.0, low_open=True)
    tour = street_tour(base.city, 1.5 * n * base.dt * speed + 10.0, np.random.default_rng(seed))
    pilot = PurePursuit(tour, speed=speed, w_max=base.W_MAX, closed=False)
    return _drive(env, pilot, pilot.start_pose(0), n, seed, progress, "drive streets")


def drive_off_lane(env: gym.Env, n: int, seed: int = 0, speed: float = CRUISE_SPEED,
                   progress: bool = True,
                   ) -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.float64]]:
    """Drive n steps off the lanes (:func:`envs.off_lane.off_lane_waypoints` drawn from
    ``seed``: weaving across the streets, U-turns, turning on the spot at corners) with
    :class:`envs.off_lane.OffLanePilot` on the true pose, from the first waypoint at a random
    heading. Arguments and returns as :func:`drive_route`."""
    base = check_city_env(env)
    _check_drive(n, seed, progress)
    speed = check_real(speed, "speed", low=0.0, low_open=True)
    pilot, start = off_lane_pilot(base, n, seed, speed)
    return _drive(env, pilot, start, n, seed, progress, "drive off lane")


def off_lane_pilot(base: Any, n: int, seed: int, speed: float = CRUISE_SPEED,
                   ) -> tuple[OffLanePilot, NDArray[np.float64]]:
    """The pilot of an n-step off-lane drive drawn from ``seed`` on the env ``base``'s city,
    and its start pose (3,)."""
    rng = np.random.default_rng(seed)
    waypoints = off_lane_waypoints(base.city, n * base.dt * speed + 10.0, rng, margin=POSE_MARGIN)
    pilot = OffLanePilot(waypoints, speed=speed, w_max=base.W_MAX)
    return pilot, pilot.start_pose(rng)


def _check_drive(n: object, seed: object, progress: object) -> None:
    check_int(n, "n", low=1)
    check_seed(seed, "seed")
    check_bool(progress, "progress")


def _drive(env: gym.Env, pilot: PurePursuit | OffLanePilot, start: NDArray[np.float64], n: int, seed: int,
           progress: bool, desc: str,
           ) -> tuple[NDArray[np.uint8], NDArray[np.float64], NDArray[np.float64]]:
    base = env.unwrapped
    obs, info = base.reset(seed=seed, options={"pose": start})
    images = np.empty((n + 1, *base.image_size, 3), np.uint8)
    poses, controls = np.empty((n + 1, 3)), np.empty((n, 2))
    images[0], poses[0] = obs["image"], info["pose"]
    for t in tqdm(range(n), desc=desc, disable=not progress, leave=False):
        controls[t] = pilot(poses[t])
        obs, _, _, _, info = base.step(controls[t])
        images[t + 1], poses[t + 1] = obs["image"], info["pose"]
    return images, poses, controls
