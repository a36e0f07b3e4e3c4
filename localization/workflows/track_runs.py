"""Closed-loop tracking runs on the pose belief (``appearance-nav track``): drive the city's
route with a pure-pursuit controller on the belief mean, for each measurement model and start
point, against dead reckoning.

For each measurement model and start point it writes ``<out>/track_<model>_<start>.png``
(top-down map with the true path, the belief with 2-sigma ellipses and the dead-reckoning
path; error over time; NEES and NIS), and ``<out>/track.json`` / ``<out>/track.md`` with the
scores (position RMSE of the belief and of dead reckoning over the same run, their ratio,
mean NEES and its chi-square band over the runs, NIS, acceptance, time per step).
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np
from tqdm import tqdm

from localization.loading import load_localizer
from localization.localizer import MEASUREMENTS, AppearanceLocalizer, city_info
from localization.workflows.plotting import plot_track
from localization.workflows.rerun_log import RerunLog, RerunRecorder
from localization.workflows.tracking import (
    fit_city_localizer,
    nees_band,
    track_metrics,
    track_route,
)

__all__ = ["TrackConfig", "run_tracking", "summarize_runs", "track_markdown"]


@dataclass
class TrackConfig:
    """Settings of the tracking runs (the options of ``appearance-nav track``)."""

    scene_seed: int = field(default=0, metadata={"help": "names the city"})
    city_size: float = field(default=20.0, metadata={
        "help": "side of the square city (m); the default 20 m city, 60 m: nine times its area"})
    camera: str = field(default="perspective", metadata={"help": "camera of the env"})
    image_size: int = field(default=64, metadata={"help": "side of the square camera image"})
    motion_noise: float = field(default=0.05, metadata={"help": "env actuation noise"})
    localizer: str = field(default="", metadata={
        "help": "a saved localizer (.npz) to use; empty: fit one on the city"})
    lanes: str = field(default="route", metadata={
        "help": "training lanes when fitting: 'route' or 'streets' (all streets, both ways)"})
    n_train: int = field(default=6000, metadata={"help": "training images when fitting"})
    n_drive: int = field(default=1000, metadata={"help": "steps of each noise drive when fitting"})
    measurements: str = field(default=",".join(MEASUREMENTS), metadata={
        "help": "comma-separated measurement models"})
    steps: int = field(default=1000, metadata={"help": "steps per tracking run"})
    starts: str = field(default="0,700,1400", metadata={
        "help": "comma-separated start points (indices of the route's path, 5 cm apart)"})
    seed: int = field(default=0, metadata={"help": "seed of the fit and the runs"})
    out: str = field(default="results", metadata={"help": "output folder"})
    allow_other_city: bool = field(default=False, metadata={
        "help": "run a localizer fitted on another city (refused by default)"})
    rerun: str = field(default="", metadata={
        "help": "also record every run to this Rerun .rrd file (the viewer extra); "
                "empty: none"})


def make_env(args: TrackConfig) -> gym.Env:
    """The env of the runs (no time limit)."""
    return gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, city_size=args.city_size,
                    camera=args.camera, image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def get_localizer(env: gym.Env, args: TrackConfig, out: Path
                  ) -> tuple[AppearanceLocalizer, dict]:
    """Load ``args.localizer`` or fit one on the city (saved to ``out/localizer.npz``)."""
    if args.localizer:
        return load_localizer(args.localizer), {}
    with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        loc, seconds = fit_city_localizer(env, args.n_train, args.lanes, args.n_drive,
                                          seed=args.seed, progress=True)
    loc.save(out / "localizer.npz")
    return loc, seconds


def track_markdown(summary: dict) -> str:
    """The markdown table of :func:`summarize_runs`."""
    lines = [("| model | runs x steps | belief RMSE (m) | dead reckoning RMSE (m) | ratio | "
              "heading RMSE (rad) | mean NEES [95 % band] | accepted | ms/step |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, s in summary.items():
        lines.append(
            f"| {name} | {s['runs']} x {s['steps']} | {s['rmse']:.3f} | "
            f"{s['rmse_dead_reckoning']:.2f} | {s['ratio']:.3f} | {s['yaw_rmse']:.3f} | "
            f"{s['nees_mean']:.2f} [{s['nees_band'][0]:.2f}, {s['nees_band'][1]:.2f}] | "
            f"{s['accepted']:.2f} | {s['ms_per_step']:.1f} |")
    return "\n".join(lines) + "\n"


def summarize_runs(rows: list[dict]) -> dict:
    """Per model: RMSE pooled over runs (root of the mean squared error), mean NEES over
    runs with the band of :func:`nees_band` for that number of runs."""
    out = {}
    for name in dict.fromkeys(r["measurement"] for r in rows):
        rs = [r for r in rows if r["measurement"] == name]
        rmse = float(np.sqrt(np.mean([r["rmse"] ** 2 for r in rs])))
        rmse_dr = float(np.sqrt(np.mean([r["rmse_dead_reckoning"] ** 2 for r in rs])))
        out[name] = {"runs": len(rs), "steps": rs[0]["steps"], "rmse": rmse,
                     "rmse_dead_reckoning": rmse_dr, "ratio": rmse / rmse_dr,
                     "worst_ratio": max(r["ratio"] for r in rs),
                     "yaw_rmse": float(np.sqrt(np.mean([r["yaw_rmse"] ** 2 for r in rs]))),
                     "nees_mean": float(np.mean([r["nees_mean"] for r in rs])),
                     "nees_band": nees_band(len(rs)),
                     "accepted": float(np.mean([r["accepted"] for r in rs])),
                     "ms_per_step": float(np.mean([r["ms_per_step"] for r in rs]))}
    return out


def run_tracking(args: TrackConfig, env: gym.Env | None = None,
               localizer: AppearanceLocalizer | None = None) -> dict:
    """Track every (model, start); write PNGs, JSON and markdown; return the results."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = env or make_env(args)
    seconds = {}
    if localizer is None:
        localizer, seconds = get_localizer(env, args, out)
    localizer.check_city(city_info(env), allow_other_city=args.allow_other_city)  # before work
    base = env.unwrapped
    rows = []
    t0 = time.perf_counter()
    runs = [(name, int(s)) for name in args.measurements.split(",")
            for s in args.starts.split(",")]
    log = RerunLog(args.rerun, base.top_down_map()) if args.rerun else None
    route = np.vstack([base.city.route(), base.city.route()[:1]])  # the closed loop driven
    for name, start in tqdm(runs, desc="tracking runs", unit="run"):
        recorder = None if log is None else partial(
            RerunRecorder, log=log, name=f"track/{name}_{start}", path=lambda: route)
        result = track_route(env, localizer, name, args.steps, start=start,
                             seed=args.seed + 100 + start,
                             allow_other_city=args.allow_other_city, recorder=recorder)
        m = track_metrics(result)
        base.set_pose(result.true[0])  # the map shows the robot at the start
        png = plot_track(result, base.render(), base.city.bounds,
                         out / f"track_{name}_{start}.png")
        rows.append({"measurement": name, "start": start, **m, "png": str(png)})
        tqdm.write(f"{name:>14} start {start:>5}: RMSE {m['rmse']:.3f} m, dead reckoning "
                   f"{m['rmse_dead_reckoning']:.2f} m (ratio {m['ratio']:.3f}), NEES "
                   f"{m['nees_mean']:.2f}, accepted {m['accepted']:.2f}")
    seconds["track"] = time.perf_counter() - t0
    if log is not None:
        log.close()
        print(f"Rerun recording: {args.rerun} (open it with: rerun {args.rerun})")
    summary = summarize_runs(rows)
    result = {"args": dataclasses.asdict(args), "seconds": seconds, "runs": rows,
              "summary": summary,
              "noise": {"control_gain": localizer.control_gain_.tolist(),
                        "consistency": {k: v.tolist() for k, v in localizer.consistency_.items()},
                        "correlation_time": {k: v[:3].tolist() for k, v in
                                             localizer.correlation_time_.items()}}}
    (out / "track.json").write_text(json.dumps(result, indent=2))
    (out / "track.md").write_text(track_markdown(summary))
    print(track_markdown(summary))
    return result
