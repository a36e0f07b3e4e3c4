"""Collect an image/pose dataset from AppearanceNav-v0 and write it to an ``.npz``
(``appearance-nav collect``).

The file holds ``images`` (n, H, W, 3) uint8, ``poses`` (n, 3) float64 ``[x, y, yaw]`` and
``meta`` (a JSON string with the settings); read it with ``envs.load_dataset``.

The n samples are collected in slices of :data:`CHUNK` (``envs.collect_dataset``'s
``start``/``stop``), one task each, by :func:`~localization.workflows.parallel.map_tasks`:
in this process, on ``workers`` local processes or on Ray, each worker building its own env.
The slices do not depend on the number of workers, so neither do the arrays. For "grid" and
"random" without randomised conditions they equal one ``collect_dataset`` call's; where each
sample draws from the env's random streams (``conditions="random"``, the "lanes" drive-in's
motion noise or traffic) each slice restarts them from its own seed
(``envs.datasets.slice_seed``). "route" is one continuous drive: one task.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from localization.workflows.parallel import (
    RAY_ADDRESS_HELP,
    WORKERS_HELP,
    close_worker_env,
    map_tasks,
    worker_env,
)

__all__ = ["CHUNK", "CollectConfig", "CollectTask", "collect_arrays", "collect_out_path",
           "collect_slice", "collect_tasks", "collect_to_file"]

#: samples per collection task (fixed: the arrays must not depend on the number of workers)
CHUNK = 500
#: the options that say how, not what, to collect (left out of the file's meta)
RUN_OPTIONS = ("workers", "ray_address")


@dataclass
class CollectConfig:
    """Settings of a collection (the options of ``appearance-nav collect``)."""

    mode: str = field(default="random", metadata={"help": "grid | random | route | lanes"})
    n: int = field(default=1000, metadata={"help": "number of samples"})
    seed: int = field(default=0, metadata={"help": "seed of the poses / the route reset"})
    scene_seed: int = field(default=0, metadata={"help": "names the city"})
    city_size: float = field(default=20.0, metadata={
        "help": "side of the square city (m); the default 20 m city, 60 m: nine times its area"})
    camera: str = field(default="perspective", metadata={
        "help": "a registered camera: " + ", ".join(sorted(envs.CAMERAS))})
    height: int = field(default=64, metadata={"help": "image height (pixels)"})
    width: int = field(default=64, metadata={"help": "image width (pixels)"})
    n_headings: int = field(default=8, metadata={
        "help": "headings per grid position (grid mode)"})
    motion_noise: float = field(default=0.0, metadata={
        "help": "actuation noise scale (route mode)"})
    conditions: str = field(default="default", metadata={
        "help": "the look (envs.conditions): a preset (dusk, night, overcast, fog, seasonal, "
                "exposure, noise, motion_blur, traffic) or 'random' (every sample its own look "
                "except in route mode: randomised training data)"})
    out: str = field(default="", metadata={
        "help": "output .npz (default data/<mode>_scene<scene_seed>_<camera>.npz)"})
    workers: int = field(default=1, metadata={"help": WORKERS_HELP})
    ray_address: str = field(default="", metadata={"help": RAY_ADDRESS_HELP})


def collect_out_path(args: CollectConfig) -> Path:
    """The file :func:`collect_to_file` writes (``.npz`` appended when missing)."""
    out = Path(args.out or f"data/{args.mode}_scene{args.scene_seed}_{args.camera}.npz")
    return out if out.suffix == ".npz" else out.with_name(out.name + ".npz")


@dataclass(frozen=True)
class CollectTask:
    """One slice ``start .. stop - 1`` of the dataset ``config`` describes."""

    config: CollectConfig
    start: int
    stop: int


def _env(c: CollectConfig) -> gym.Env:
    """The env of ``c``'s settings (kept while the next slice shares them)."""
    key = (c.scene_seed, c.city_size, c.camera, c.height, c.width, c.motion_noise, c.conditions)
    return worker_env(key, lambda: gym.make(
        "AppearanceNav-v0", scene_seed=c.scene_seed, city_size=c.city_size, camera=c.camera,
        image_size=(c.height, c.width), motion_noise=c.motion_noise, conditions=c.conditions))


def collect_slice(task: CollectTask,
                  ) -> tuple[NDArray[np.uint8], NDArray[np.float64], dict[str, float]]:
    """Samples ``task.start .. task.stop - 1``: images (m, H, W, 3) uint8, poses (m, 3)
    float64, and the env's ``dt`` and ``city_size`` with the slice's ``cpu_seconds``."""
    c, cpu = task.config, time.process_time()
    env = _env(c)
    images, poses = envs.collect_dataset(env, c.n, c.mode, seed=c.seed, n_headings=c.n_headings,
                                         progress=False, start=task.start, stop=task.stop)
    return images, poses, {"dt": env.unwrapped.dt, "city_size": env.unwrapped.city.size,
                           "cpu_seconds": time.process_time() - cpu}


def collect_tasks(args: CollectConfig) -> list[CollectTask]:
    """The slices of :data:`CHUNK` samples ("route": one task, the whole drive)."""
    step = args.n if args.mode == "route" else CHUNK
    return [CollectTask(args, a, min(a + step, args.n)) for a in range(0, args.n, step)]


def collect_arrays(args: CollectConfig, progress: bool = True,
                   ) -> tuple[NDArray[np.uint8], NDArray[np.float64], dict]:
    """Collect ``args.n`` samples with ``args.workers`` workers (or on Ray).

    Returns
    -------
    images : (n, H, W, 3) uint8
    poses : (n, 3) float64 ``[x, y, yaw]``
    info : dict — ``dt`` and ``city_size`` of the env, and ``cpu_seconds``: the CPU time of
        the slices (the env builds included, the worker start-up not).
    """
    tasks = collect_tasks(args)
    try:
        parts = map_tasks(collect_slice, tasks, workers=args.workers,
                          ray_address=args.ray_address, progress=progress,
                          desc=f"collect {args.mode} ({len(tasks)} slices)")
    finally:
        close_worker_env()  # the serial run's
    info = {**parts[0][2], "cpu_seconds": sum(p[2]["cpu_seconds"] for p in parts)}
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), info


def collect_to_file(args: CollectConfig) -> Path:
    """Collect ``args.n`` images and poses (progress bar) and save them; returns the file."""
    out = collect_out_path(args)
    t0 = time.perf_counter()
    images, poses, info = collect_arrays(args)
    seconds = time.perf_counter() - t0
    settings = {k: v for k, v in dataclasses.asdict(args).items() if k not in RUN_OPTIONS}
    settings.update(dt=info["dt"], city_size=info["city_size"],
                    chunk=CHUNK if args.mode != "route" else args.n)
    path = envs.save_dataset(out, images, poses, **settings)
    print(f"wrote {path}: images {images.shape}, poses {poses.shape} in {seconds:.1f} s "
          f"({args.n / seconds:.0f} samples/s, {args.workers} worker(s)"
          f"{' on Ray' if args.ray_address else ''})")
    return path
