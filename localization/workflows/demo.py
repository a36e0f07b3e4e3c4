"""The main job (``make demo``, ``appearance-nav demo``): the whole pipeline on the default
city.

Stages:

1. build the city, drive the robot once around its street loop (``envs.collect_dataset``
   in "route" mode), save the dataset to ``<out>/route_dataset.npz`` and write
   ``<out>/demo_route.png``: the map with the driven route beside camera images along it;
2. collect training images around the driving lanes (every street both ways and every turn
   with ``lanes="streets"``, so agents can use the localizer anywhere; only the route's with
   ``lanes="route"``) and fit the :class:`AppearanceLocalizer` (features + GSE); estimate the
   noise model on a drive where the lanes go (random street tours, or around the route) and
   calibrate it on a drive on the belief
   (:func:`localization.workflows.tracking.fit_city_localizer`); save it to
   ``<out>/localizer.npz``;
3. closed-loop tracking: for each measurement model drive ``steps`` steps of the route
   with a pure-pursuit controller on the belief mean, against dead reckoning; write
   ``<out>/track_<model>.png`` and print the results table (also ``<out>/demo.md``);
   then the appearance stage (``dusk``): the same route driven at dusk (or another
   ``conditions`` preset) on the daylight localizer, ``<out>/track_dusk.png``, and
   (``dusk_map``) on a daylight map of the route with patch-normalised features (the
   appearance benchmark's, :data:`DUSK_MAP`), ``<out>/track_dusk_patches.png``;
   then the kidnapping stage (``kidnap``): one unannounced kidnap on a street drive, the EKF
   without and with divergence detection and the particle belief side by side,
   ``<out>/kidnap.png``
   (:func:`localization.workflows.kidnap_demo.kidnap_demo`); then the episode video
   (``video``): the scripted agent on the particle belief through a kidnap,
   ``<out>/episode.mp4`` (:func:`localization.workflows.episode_video.episode_video`;
   ``rerun``: the same episode as a Rerun recording);
4. navigation: the scripted agent (street planner + pure pursuit) drives ``episodes``
   seeded episodes to random goals on each pose source (true pose, belief, dead reckoning;
   :func:`localization.workflows.navigation.evaluate_agents`), table in
   ``<out>/demo_agents/agents.md``.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import gymnasium as gym

from localization.localizer import MEASUREMENTS, AppearanceLocalizer
from localization.workflows.episode_video import episode_video
from localization.workflows.kidnap_demo import kidnap_demo
from localization.workflows.navigation import EvalConfig, evaluate_agents
from localization.workflows.plotting import plot_route, plot_track
from localization.workflows.quality import quality_table
from localization.workflows.tracking import fit_city_localizer, track_metrics, track_route

__all__ = ["DUSK_MAP", "DemoConfig", "demo_table", "run_demo"]

#: the appearance stage's daylight map of the route: the appearance benchmark's features
#: (PixelPCA(128) on 8 x 8 patch-normalised pixels, chosen on tuning cities 11-12, checked on 13-14), fewer
#: images, the noise of the one measurement model the stage drives
DUSK_MAP = {"n_train": 6000, "lanes": "route", "n_drive": 1500,
            "measurements": ("representation",),
            "localizer_params": {"features_params": {"n_components": 128,
                                                     "normalize": "patches"}}}


@dataclass
class DemoConfig:
    """Settings of the demo (the options of ``appearance-nav demo``)."""

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
    dusk: str = field(default="dusk", metadata={
        "help": "the appearance stage: one route drive under this conditions preset on the "
                "daylight localizer, <out>/track_<preset>.png ('' to skip)"})
    dusk_map: bool = field(default=True, metadata={
        "help": "the appearance stage also fits a daylight map of the route with "
                "patch-normalised features (6000 images, about 80 s) and drives the same "
                "route on it, <out>/track_<preset>_patches.png"})
    kidnap: bool = field(default=True, metadata={
        "help": "the kidnapping stage: the EKFs and the particle belief through one "
                "unannounced kidnap"})
    video: bool = field(default=True, metadata={
        "help": "the episode video: the scripted agent on the particle belief through a "
                "kidnap, <out>/episode.mp4"})
    rerun: str = field(default="", metadata={
        "help": "also record the video's episode to this Rerun .rrd file (the viewer "
                "extra); empty: none"})
    episodes: int = field(default=30, metadata={
        "help": "navigation episodes of the scripted agent per pose source (0: skip)"})
    out: str = field(default="results", metadata={"help": "output folder"})


def demo_table(rows: list[dict]) -> str:
    """The markdown table of the tracking rows."""
    lines = [("| measurement model | steps | belief RMSE (m) | dead reckoning RMSE (m) | ratio | "
              "heading RMSE (rad) | mean NEES | accepted | ms/step |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['measurement']} | {r['steps']} | {r['rmse']:.3f} | "
                     f"{r['rmse_dead_reckoning']:.2f} | {r['ratio']:.3f} | {r['yaw_rmse']:.3f} | "
                     f"{r['nees_mean']:.2f} | {r['accepted']:.2f} | {r['ms_per_step']:.1f} |")
    return "\n".join(lines) + "\n"


def _navigate(args: DemoConfig, out: Path) -> list[dict]:
    """Stage 4: the scripted agent on every pose source."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        return evaluate_agents(EvalConfig(
            agents="scripted", episodes=args.episodes, localizer=str(out / "localizer.npz"),
            scene_seed=args.scene_seed, camera=args.camera, image_size=args.image_size,
            motion_noise=args.motion_noise, out=str(out / "demo_agents")))


def _video(args: DemoConfig, loc: AppearanceLocalizer, out: Path, seconds: dict) -> dict:
    """The episode video stage (and its Rerun recording with ``--rerun``)."""
    t1 = time.perf_counter()
    video = episode_video(loc, out / "episode.mp4", scene_seed=args.scene_seed,
                          camera=args.camera, image_size=args.image_size,
                          motion_noise=args.motion_noise, seed=args.seed,
                          rerun=args.rerun or None)
    seconds["video"] = time.perf_counter() - t1
    print(f"[demo] episode video: {video['frames']} frames, kidnapped at step "
          f"{video['kidnap_step']}, back within 1 m after {video['steps_to_recover']} steps, "
          f"goal {'reached' if video['success'] else 'not reached'}; {video['mp4']}"
          + (f"; Rerun: rerun {args.rerun}" if args.rerun else ""), flush=True)
    return video


def _env(args: DemoConfig, conditions: str | None = None) -> gym.Env:
    """The demo's city and camera in the look ``conditions`` (None: today's), without a step
    limit."""
    return gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, camera=args.camera,
                    conditions=conditions, image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def _appearance(args: DemoConfig, loc: AppearanceLocalizer, out: Path) -> list[dict]:
    """The appearance stage: the tracking route under ``args.dusk`` on the daylight
    localizer ("representation" model), as the tracking stage drives it in daylight; with
    ``args.dusk_map`` also on a daylight map of the route with patch-normalised features."""
    env = _env(args, args.dusk)
    try:
        maps = [("", "the localizer fitted in daylight", loc)]
        if args.dusk_map:
            maps.append(("_patches", "a daylight route map, patch-normalised",
                         _dusk_map(args)))
        return [_drive_under(args, env, m, out, suffix, label)
                for suffix, label, m in maps]
    finally:
        env.close()


def _dusk_map(args: DemoConfig) -> AppearanceLocalizer:
    """A daylight map of the route with patch-normalised features (:data:`DUSK_MAP`)."""
    day = _env(args)
    try:
        with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            return fit_city_localizer(day, seed=args.seed, **DUSK_MAP)[0]
    finally:
        day.close()


def _drive_under(args: DemoConfig, env: gym.Env, loc: AppearanceLocalizer, out: Path,
                 suffix: str, label: str) -> dict:
    """One tracking-route drive under the env's look on ``loc``: its row and PNG."""
    run = track_route(env, loc, "representation", args.steps, start=args.start,
                      seed=args.seed + 7)
    env.unwrapped.set_pose(run.true[0])
    png = plot_track(run, env.unwrapped.render(), env.unwrapped.city.bounds,
                     out / f"track_{args.dusk}{suffix}.png", title=f"{args.dusk}, on {label}")
    name = f"representation, {args.dusk}" + (f" ({label})" if suffix else "")
    return {"measurement": name, **track_metrics(run), "png": str(png)}


def run_demo(args: DemoConfig) -> dict:
    """Run the four stages; write the dataset, the localizer, PNGs, ``demo.md`` and
    ``demo.json`` to ``args.out``; return the summary of ``demo.json``."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    seconds = {}
    env = _env(args)
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
    print(f"[demo] localizer quality (held-out drive, {loc.quality_['steps']:.0f} steps):\n"
          f"{quality_table(loc.quality_)}", flush=True)
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
    if args.dusk:
        t1 = time.perf_counter()
        for row in _appearance(args, loc, out):
            rows.append(row)
            print(f"[demo] {row['measurement']}: RMSE {row['rmse']:.3f} m vs dead "
                  f"reckoning {row['rmse_dead_reckoning']:.2f} m; {row['png']}", flush=True)
        seconds["appearance"] = time.perf_counter() - t1
    kidnap = {}
    if args.kidnap:
        t1 = time.perf_counter()
        kidnap = kidnap_demo(env, loc, out, seed=args.seed + 11)
        seconds["kidnap"] = time.perf_counter() - t1
        print(f"[demo] kidnapped after {kidnap['kidnap_step']} steps; steps to recover: "
              f"{kidnap['steps_to_recover']} (None: not within the drive); {kidnap['png']}",
              flush=True)
    env.close()
    video = _video(args, loc, out, seconds) if args.video or args.rerun else {}
    table = demo_table(rows)
    (out / "demo.md").write_text(table)
    navigation = []
    if args.episodes > 0:
        t1 = time.perf_counter()
        navigation = _navigate(args, out)
        seconds["navigate"] = time.perf_counter() - t1
    seconds["total"] = time.perf_counter() - t0
    summary = {"dataset": str(dataset), "route_png": str(figure), "frames": len(poses),
               "localizer": str(out / "localizer.npz"), "tracking": rows,
               "navigation": navigation, "kidnap": kidnap, "video": video,
               "control_gain": loc.control_gain_.tolist(),
               "consistency": {k: v.tolist() for k, v in loc.consistency_.items()},
               "quality": loc.quality_,
               "seconds": {k: round(v, 1) for k, v in seconds.items()}}
    (out / "demo.json").write_text(json.dumps(summary, indent=2))
    print(f"\nClosed-loop tracking, city {args.scene_seed}, {args.steps} steps along the route "
          f"(motion noise {args.motion_noise}; dead reckoning: F alone from the true start):\n")
    print(table)
    print(f"[demo] done in {seconds['total']:.0f} s; PNGs and JSON in {out}/")
    return summary
