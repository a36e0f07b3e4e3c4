"""Image/pose datasets from the city: collect, save, load.

``collect_dataset(env, n, mode, seed)`` returns ``images`` (n, H, W, 3) uint8 and the
true ``poses`` (n, 3) float64 ``[x, y, yaw]``:

- ``"grid"``: a regular grid of street positions times ``n_headings`` headings (the
  grid spacing is the largest giving at least n poses; n of them are taken evenly);
- ``"random"``: uniform random free poses;
- ``"route"``: the robot drives (physics, the env's motion noise) around
  ``city.route()`` with a pure-pursuit controller; one sample per env step.

For "grid" and "random" the robot is teleported (``mj_forward``) and the camera
rendered, which is fast.
"""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

from envs.motion_model import wrap_angle
from envs.robot import ROBOT_RADIUS

__all__ = ["MODES", "PurePursuit", "collect_dataset", "grid_poses", "load_dataset", "save_dataset"]

MODES = ("grid", "random", "route")
POSE_MARGIN = ROBOT_RADIUS + 0.1  # m of clearance to buildings for teleported poses


def grid_poses(city: Any, n: int, n_headings: int = 8, margin: float = POSE_MARGIN) -> NDArray[np.float64]:
    """Return n poses (n, 3) from a regular grid of free positions x ``n_headings`` headings."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
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
    """Pure-pursuit steering around a closed polyline, like a car following a lane.

    Parameters
    ----------
    waypoints : (p, 2) closed loop (the last point connects back to the first).
    lookahead : float — distance (m) to the carrot point along the path.
    speed : float — forward speed command (m/s).
    w_max : float — bound on the angular velocity command (rad/s).
    step : float — path resampling step (m).
    """

    def __init__(self, waypoints: NDArray[np.float64], lookahead: float = 0.8, speed: float = 0.6,
                 w_max: float = 1.0, step: float = 0.05) -> None:
        loop = np.vstack([waypoints, waypoints[:1]])
        pts = [a + (b - a) * t for a, b in pairwise(loop)
               for t in np.arange(0, 1, step / max(np.hypot(*(b - a)), 1e-9))]
        self.path = np.array(pts)
        self.lookahead, self.speed, self.w_max, self.step = lookahead, speed, w_max, step
        self.index = 0

    def start_pose(self) -> NDArray[np.float64]:
        """The first path point, heading along the path, (3,)."""
        d = self.path[1] - self.path[0]
        return np.array([*self.path[0], np.arctan2(d[1], d[0])])

    def __call__(self, pose: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return the control U = [v, w] for the current pose."""
        n = len(self.path)
        window = (self.index + np.arange(40)) % n  # search only ahead: the loop crosses itself
        d = np.hypot(*(self.path[window] - pose[:2]).T)
        self.index = int(window[np.argmin(d)])
        carrot = self.path[(self.index + int(self.lookahead / self.step)) % n]
        alpha = wrap_angle(np.arctan2(carrot[1] - pose[1], carrot[0] - pose[0]) - pose[2])
        w = np.clip(2.0 * self.speed * np.sin(alpha) / self.lookahead, -self.w_max, self.w_max)
        v = self.speed * max(0.3, np.cos(alpha))  # slow down in sharp turns
        return np.array([v, w])


def collect_dataset(env: gym.Env, n: int, mode: str = "random", seed: int = 0, n_headings: int = 8,
                    progress: bool = True) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """Collect n camera images with their true poses.

    Parameters
    ----------
    env : an AppearanceNav env (wrapped or not).
    n : int — number of samples.
    mode : "grid", "random" or "route" (see the module docstring).
    seed : int — seeds the random poses / the env reset for "route".
    n_headings : int — headings per grid position ("grid" only).
    progress : bool — show a tqdm progress bar.

    The env's state is changed (teleports, or a reset and a drive for "route"): reset it
    before running episodes on it.

    Returns
    -------
    images : (n, H, W, 3) uint8
    poses : (n, 3) float64 ``[x, y, yaw]``
    """
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; known modes: {list(MODES)}")
    if int(n) != n or n < 1:
        raise ValueError(f"n must be a positive integer, got {n}")
    base = env.unwrapped
    city = base.city
    images = np.empty((n, *base.image_size, 3), np.uint8)
    poses = np.empty((n, 3))
    bar = tqdm(total=n, desc=f"collect {mode}", disable=not progress, leave=False)
    if mode == "route":
        pilot = PurePursuit(city.route(), w_max=base.W_MAX)
        obs, info = base.reset(seed=seed, options={"pose": pilot.start_pose()})
        pose = info["pose"]
        for i in range(n):
            obs, _, _, _, info = base.step(pilot(pose))
            pose = info["pose"]
            images[i], poses[i] = obs["image"], pose
            bar.update()
    else:
        if mode == "grid":
            targets = grid_poses(city, n, n_headings)
        else:
            rng = np.random.default_rng(seed)
            targets = np.array([city.random_free_pose(rng, POSE_MARGIN) for _ in range(n)])
        for i, target in enumerate(targets):
            base.set_pose(target)
            images[i], poses[i] = base.render_camera(), base.pose
            bar.update()
    bar.close()
    return images, poses


def save_dataset(path: str | Path, images: NDArray[np.uint8], poses: NDArray[np.float64], **meta: Any) -> Path:
    """Save to a compressed ``.npz`` with ``images``, ``poses`` and ``meta`` (a JSON string).

    Raises
    ------
    ValueError
        On mismatched shapes/dtypes or metadata that is not JSON-serialisable.
    """
    images, poses = _check_arrays(np.asarray(images), np.asarray(poses), str(path))
    try:
        meta_json = json.dumps(meta, sort_keys=True)
    except TypeError as err:
        raise ValueError(f"dataset metadata must be JSON-serialisable: {err}") from None
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, images=images, poses=poses, meta=np.array(meta_json))
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def load_dataset(path: str | Path) -> tuple[NDArray[np.uint8], NDArray[np.float64], dict[str, Any]]:
    """Load ``(images, poses, meta)`` saved by :func:`save_dataset`.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is not a readable npz, lacks an array, or the arrays are inconsistent.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no dataset at {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in ("images", "poses", "meta") if k in z.files}
    except Exception as err:  # zipfile.BadZipFile, OSError, EOFError, zlib errors, pickled data...
        raise ValueError(f"dataset {path} is corrupted or not an npz file: {err}") from err
    missing = [k for k in ("images", "poses", "meta") if k not in arrays]
    if missing:
        raise ValueError(f"dataset {path} lacks arrays {missing}")
    images, poses, meta_json = arrays["images"], arrays["poses"], str(arrays["meta"])
    try:
        meta = json.loads(meta_json)
    except json.JSONDecodeError as err:
        raise ValueError(f"dataset {path} has corrupted metadata: {err}") from None
    images, poses = _check_arrays(images, poses, str(path))
    return images, poses, meta


def _check_arrays(images: NDArray[Any], poses: NDArray[Any], where: str) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"{where}: images must be (n, H, W, 3) uint8, got {images.shape} {images.dtype}")
    if poses.shape != (len(images), 3):
        raise ValueError(f"{where}: poses must have shape ({len(images)}, 3), got {poses.shape}")
    if not np.all(np.isfinite(poses)):
        raise ValueError(f"{where}: poses contain NaN or inf")
    return images, poses.astype(np.float64)
