"""The main job (``make demo``): the whole pipeline on the default city.

CleanRL style: one file, every setting a field of ``Args`` (``--help`` lists them).

    python scripts/demo.py                 # default city (scene seed 0), results/ as output
    python scripts/demo.py --scene-seed 3 --n-route 1500

Stages so far:

1. build the city, drive the robot once around its street loop (``envs.collect_dataset``
   in "route" mode) and save the dataset to ``<out>/route_dataset.npz``;
2. write ``<out>/demo_route.png``: the top-down map with the driven route, beside a strip
   of camera images taken along it.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import gymnasium as gym
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt


@dataclass
class Args:
    scene_seed: int = field(default=0, metadata={"help": "names the city (0 = the default city)"})
    camera: str = field(default="perspective", metadata={
        "help": "a registered camera: " + ", ".join(sorted(envs.CAMERAS))})
    image_size: int = field(default=64, metadata={"help": "side of the square camera image"})
    n_route: int = field(default=2500, metadata={"help": "frames driven along the route"})
    seed: int = field(default=0, metadata={"help": "seed of the route drive"})
    strip: int = field(default=8, metadata={"help": "camera images shown in the strip"})
    out: str = field(default="results", metadata={"help": "output folder"})


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse ``--field-name value`` options built from the fields of ``Args``."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    for f in dataclasses.fields(Args):
        parser.add_argument("--" + f.name.replace("_", "-"), type=type(f.default),
                            default=f.default, help=f"{f.metadata['help']} (default: {f.default!r})")
    return Args(**vars(parser.parse_args(argv)))


def plot_route(env: gym.Env, images: np.ndarray, poses: np.ndarray, n_strip: int,
               path: Path) -> Path:
    """Top-down map with the driven route and the frames of the strip marked, plus the strip."""
    base = env.unwrapped
    lo, hi = base.city.bounds
    top = base.render()
    picks = np.linspace(0, len(poses) - 1, n_strip).round().astype(int)
    fig = plt.figure(figsize=(2.0 * n_strip, 2.0 * n_strip / 2 + 2.4))
    grid = fig.add_gridspec(2, n_strip, height_ratios=[n_strip / 2, 1])
    ax = fig.add_subplot(grid[0, :])
    ax.imshow(top, extent=(lo, hi, lo, hi))
    ax.plot(poses[:, 0], poses[:, 1], "-", color="tab:orange", lw=1.5, label="driven route")
    for k, i in enumerate(picks):
        x, y, yaw = poses[i]
        ax.annotate("", (x + 0.8 * np.cos(yaw), y + 0.8 * np.sin(yaw)), (x, y),
                    arrowprops={"arrowstyle": "->", "color": "tab:cyan", "lw": 1.5})
        ax.text(x, y, f" {k + 1}", color="white", fontsize=9, weight="bold")
    ax.set_title(f"city {base.city.seed}: {len(poses)} frames along the route "
                 f"({np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T)):.0f} m)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=8)
    for k, i in enumerate(picks):
        a = fig.add_subplot(grid[1, k])
        a.imshow(images[i])
        a.set_title(f"{k + 1}: ({poses[i, 0]:.1f}, {poses[i, 1]:.1f}, "
                    f"{np.degrees(poses[i, 2]):.0f}°)", fontsize=7)
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    env = gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, camera=args.camera,
                   image_size=(args.image_size, args.image_size))
    images, poses = envs.collect_dataset(env, args.n_route, "route", seed=args.seed)
    dataset = envs.save_dataset(out / "route_dataset.npz", images, poses,
                                **dataclasses.asdict(args), dt=env.unwrapped.dt)
    figure = plot_route(env, images, poses, args.strip, out / "demo_route.png")
    env.close()
    summary = {"dataset": str(dataset), "route_png": str(figure), "frames": len(poses),
               "seconds": round(time.perf_counter() - t0, 1)}
    (out / "demo.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return summary


if __name__ == "__main__":
    main()
