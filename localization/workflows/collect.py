"""Collect an image/pose dataset from AppearanceNav-v0 and write it to an ``.npz``
(``appearance-nav collect``).

The file holds ``images`` (n, H, W, 3) uint8, ``poses`` (n, 3) float64 ``[x, y, yaw]`` and
``meta`` (a JSON string with the settings); read it with ``envs.load_dataset``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import gymnasium as gym

__all__ = ["CollectConfig", "collect_out_path", "collect_to_file"]


@dataclass
class CollectConfig:
    """Settings of a collection (the options of ``appearance-nav collect``)."""

    mode: str = field(default="random", metadata={"help": "grid | random | route | lanes"})
    n: int = field(default=1000, metadata={"help": "number of samples"})
    seed: int = field(default=0, metadata={"help": "seed of the poses / the route reset"})
    scene_seed: int = field(default=0, metadata={"help": "names the city"})
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


def collect_out_path(args: CollectConfig) -> Path:
    """The file :func:`collect_to_file` writes (``.npz`` appended when missing)."""
    out = Path(args.out or f"data/{args.mode}_scene{args.scene_seed}_{args.camera}.npz")
    return out if out.suffix == ".npz" else out.with_name(out.name + ".npz")


def collect_to_file(args: CollectConfig) -> Path:
    """Collect ``args.n`` images and poses (progress bar) and save them; returns the file."""
    out = collect_out_path(args)
    env = gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, camera=args.camera,
                   image_size=(args.height, args.width), motion_noise=args.motion_noise,
                   conditions=args.conditions)
    t0 = time.perf_counter()
    images, poses = envs.collect_dataset(env, args.n, args.mode, seed=args.seed,
                                         n_headings=args.n_headings)
    seconds = time.perf_counter() - t0
    env.close()
    path = envs.save_dataset(out, images, poses, **dataclasses.asdict(args), dt=env.unwrapped.dt,
                             city_size=env.unwrapped.city.size)
    print(f"wrote {path}: images {images.shape}, poses {poses.shape} in {seconds:.1f} s "
          f"({args.n / seconds:.0f} samples/s)")
    return path
