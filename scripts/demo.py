"""The main job (``make demo``): the whole pipeline on the default city.

CleanRL style: one file, every setting a field of ``Args`` (``--help`` lists them).

    python scripts/demo.py                 # default city (scene seed 0), results/ as output
    python scripts/demo.py --scene-seed 3 --lanes route

Stages:

1. build the city, drive the robot once around its street loop (``envs.collect_dataset``
   in "route" mode), save the dataset to ``<out>/route_dataset.npz`` and write
   ``<out>/demo_route.png``: the map with the driven route beside camera images along it;
2. collect training images around the driving lanes (every street both ways and every turn
   with ``--lanes streets``, so agents can use the localizer anywhere; only the route's with
   ``--lanes route``) and fit the :class:`AppearanceLocalizer` (features + GSE); estimate the
   noise model on a drive where the lanes go (random street tours, or around the route) and
   calibrate it on a drive on the belief
   (``localization.workflows.tracking.fit_city_localizer``); save it to ``<out>/localizer.npz``;
3. closed-loop tracking: for each measurement model drive ``--steps`` steps of the route
   with a pure-pursuit controller on the belief mean, against dead reckoning; write
   ``<out>/track_<model>.png`` and print the results table (also ``<out>/demo.md``);
4. navigation: the scripted agent (street planner + pure pursuit) drives ``--episodes``
   seeded episodes to random goals on each pose source (true pose, belief, dead reckoning;
   ``scripts/eval_agents.py``), table in ``<out>/demo_agents/agents.md``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "scripts"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import warnings

import eval_agents
import gymnasium as gym
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from cli import parse_dataclass_args

from localization.localizer import MEASUREMENTS
from localization.workflows.plotting import plot_track
from localization.workflows.tracking import fit_city_localizer, track_metrics, track_route


@dataclass
class Args:
    scene_seed: int = field(default=0, metadata={"help": "names the city (0 = the default city)"})
    camera: str = field(default="perspective", metadata={
        "help": "a registered camera: " + ", ".join(sorted(envs.CAMERAS))})
    image_size: int = field(default=64, metadata={"help": "side of the square camera image"})
    n_route: int = field(default=2500, metadata={"help": "frames driven along the route"})
    seed: int = field(default=0, metadata={"help": "seed of the route drive and the fit"})
    strip: int = field(default=8, metadata={"help": "camera images shown in the strip"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    lanes: str = field(default="streets", metadata={
        "help": "training lanes: 'streets' (all, both ways) or 'route'"})
    n_train: int = field(default=20000, metadata={"help": "training images around the lanes"})
    n_drive: int = field(default=1000, metadata={"help": "steps of each noise drive"})
    steps: int = field(default=1000, metadata={"help": "steps of each tracking run"})
    start: int = field(default=0, metadata={"help": "tracking start (route path point)"})
    episodes: int = field(default=30, metadata={
        "help": "navigation episodes of the scripted agent per pose source (0: skip)"})
    out: str = field(default="results", metadata={"help": "output folder"})


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse ``--field-name value`` options built from the fields of ``Args``."""
    return parse_dataclass_args(Args, __doc__, argv)


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


def results_table(rows: list[dict]) -> str:
    lines = [("| measurement model | steps | belief RMSE (m) | dead reckoning RMSE (m) | ratio | "
              "heading RMSE (rad) | mean NEES | accepted | ms/step |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['measurement']} | {r['steps']} | {r['rmse']:.3f} | "
                     f"{r['rmse_dead_reckoning']:.2f} | {r['ratio']:.3f} | {r['yaw_rmse']:.3f} | "
                     f"{r['nees_mean']:.2f} | {r['accepted']:.2f} | {r['ms_per_step']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    seconds = {}
    env = gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, camera=args.camera,
                   image_size=(args.image_size, args.image_size),
                   motion_noise=args.motion_noise, max_episode_steps=None)
    images, poses = envs.collect_dataset(env, args.n_route, "route", seed=args.seed)
    dataset = envs.save_dataset(out / "route_dataset.npz", images, poses,
                                **dataclasses.asdict(args), dt=env.unwrapped.dt)
    figure = plot_route(env, images, poses, args.strip, out / "demo_route.png")
    seconds["route"] = time.perf_counter() - t0
    print(f"[demo] route dataset and map: {seconds['route']:.0f} s", flush=True)
    with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        loc, fit_seconds = fit_city_localizer(env, args.n_train, args.lanes, args.n_drive,
                                              seed=args.seed, progress=True)
    seconds.update(fit_seconds)
    loc.save(out / "localizer.npz")
    print(f"[demo] localizer: {args.n_train} images ({args.lanes} lanes) collected in "
          f"{fit_seconds['collect']:.0f} s, fitted in {fit_seconds['fit']:.0f} s, noise model "
          f"in {fit_seconds['noise']:.0f} s", flush=True)
    t1 = time.perf_counter()
    rows = []
    for name in MEASUREMENTS:
        run = track_route(env, loc, name, args.steps, start=args.start, seed=args.seed + 7)
        m = track_metrics(run)
        env.unwrapped.set_pose(run.true[0])  # the map shows the robot at the start
        png = plot_track(run, env.unwrapped.render(), env.unwrapped.city.bounds,
                         out / f"track_{name}.png")
        rows.append({"measurement": name, **m, "png": str(png)})
        print(f"[demo] {name}: RMSE {m['rmse']:.3f} m vs dead reckoning "
              f"{m['rmse_dead_reckoning']:.2f} m", flush=True)
    seconds["track"] = time.perf_counter() - t1
    env.close()
    table = results_table(rows)
    (out / "demo.md").write_text(table)
    navigation = []
    if args.episodes > 0:
        t1 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            navigation = eval_agents.main([
                "--agents", "scripted", "--episodes", str(args.episodes),
                "--localizer", str(out / "localizer.npz"), "--scene-seed", str(args.scene_seed),
                "--camera", args.camera, "--image-size", str(args.image_size),
                "--motion-noise", str(args.motion_noise), "--out", str(out / "demo_agents")])
        seconds["navigate"] = time.perf_counter() - t1
    seconds["total"] = time.perf_counter() - t0
    summary = {"dataset": str(dataset), "route_png": str(figure), "frames": len(poses),
               "localizer": str(out / "localizer.npz"), "tracking": rows,
               "navigation": navigation,
               "control_gain": loc.control_gain_.tolist(),
               "consistency": {k: v.tolist() for k, v in loc.consistency_.items()},
               "seconds": {k: round(v, 1) for k, v in seconds.items()}}
    (out / "demo.json").write_text(json.dumps(summary, indent=2))
    print(f"\nClosed-loop tracking, city {args.scene_seed}, {args.steps} steps along the route "
          f"(motion noise {args.motion_noise}; dead reckoning: F alone from the true start):\n")
    print(table)
    print(f"[demo] done in {seconds['total']:.0f} s; PNGs and JSON in {out}/")
    return summary


if __name__ == "__main__":
    main()
