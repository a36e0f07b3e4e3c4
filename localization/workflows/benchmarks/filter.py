"""Benchmark of the pose belief: the wrapper's per-step cost and closed-loop tracking accuracy
(``appearance-nav bench --only filter``; its options are ``--filter-<option>``).

    appearance-nav bench --only filter                  # PixelPCA and the DCNN (EfficientNet-Lite0)
    appearance-nav bench --only filter --filter-quick   # smoke run

What is measured
----------------
* Overhead (per model, per feature extractor): the bare env (``AppearanceNav-v0``) and the
  same env under :class:`BeliefWrapper` are stepped with the same pure-pursuit actions,
  alternating in chunks of ``chunk`` steps in one run; overhead = median wrapped step -
  median bare step. Broken down on the frames of the run: features (``transform``), the GSE
  query (``measure`` plus ``h``/``H``/``R`` at the prior), the EKF predict + update.
  Targets: <= 5 ms per step with PixelPCA, <= 40 ms with the DCNN (EfficientNet-Lite0).
* Tracking (PixelPCA localizer fitted on the city, noise calibrated as in
  ``localization.workflows.tracking.fit_city_localizer``): ``runs`` closed-loop runs of ``steps`` steps
  along the route per model; position RMSE of the belief vs dead reckoning (F alone from the
  true start pose, same controls). Target: RMSE <= 0.10 x dead reckoning over 1000 steps.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np

from envs.datasets import PurePursuit, collect_dataset, drive_route
from localization.localizer import MEASUREMENTS, AppearanceLocalizer
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.tracking import fit_city_localizer, track_metrics, track_route
from localization.wrappers import BeliefWrapper

TARGET_MS = {"pixel_pca": 5.0, "efficientnet": 40.0}
TARGET_RATIO = 0.10

__all__ = ["TARGET_MS", "TARGET_RATIO", "FilterBenchConfig", "run_filter_bench"]


@dataclass
class FilterBenchConfig:
    """Settings of the filter benchmark."""

    scene_seed: int = field(default=0, metadata={"help": "city of the benchmark"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    n_train: int = field(default=6000, metadata={"help": "training images (PixelPCA)"})
    n_train_dcnn: int = field(default=1500, metadata={
        "help": "training images of the DCNN localizer (overhead only: its cost per step "
                "hardly depends on n)"})
    n_drive: int = field(default=1000, metadata={"help": "steps of each noise drive"})
    steps: int = field(default=1000, metadata={"help": "steps per tracking run"})
    runs: int = field(default=3, metadata={"help": "tracking runs per model (starts along the route)"})
    overhead_steps: int = field(default=400, metadata={"help": "timed steps per overhead loop"})
    chunk: int = field(default=50, metadata={"help": "bare and wrapped env alternate every this many steps"})
    no_dcnn: bool = field(default=False, metadata={"help": "skip the DCNN overhead"})
    quick: bool = field(default=False, metadata={"help": "smoke run: small fits, short runs"})
    seed: int = field(default=0, metadata={"help": "seed of fits and runs"})
    out_dir: str = field(default="results", metadata={"help": "where bench_filter.json/.md go"})


    def resolved(self) -> FilterBenchConfig:
        """The settings actually run (``quick``: small fits, short runs)."""
        if not self.quick:
            return self
        return dataclasses.replace(self, n_train=1500, n_train_dcnn=400, n_drive=400,
                                   steps=200, runs=1, overhead_steps=100, chunk=25)


def make_env(args: FilterBenchConfig) -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=args.scene_seed,
                    motion_noise=args.motion_noise, max_episode_steps=None)


def timed(fn, *a) -> float:
    t0 = time.perf_counter()
    fn(*a)
    return time.perf_counter() - t0


def overhead(args: FilterBenchConfig, loc: AppearanceLocalizer, measurement: str) -> dict:
    """Median per-step times (ms): bare env, wrapped env (two envs of the same city, stepped
    alternately), and the wrapper's parts."""
    bare = make_env(args).unwrapped
    env = make_env(args)
    base = env.unwrapped
    wrapped = BeliefWrapper(env, loc, measurement)
    start = PurePursuit(base.city.route()).start_pose(0)
    bare_t, wrap_t = [], []
    pilot_b, pilot_w = (PurePursuit(base.city.route(), w_max=1.0) for _ in range(2))
    pilot_b.start_pose(0)
    pilot_w.start_pose(0)
    _, info = bare.reset(seed=args.seed, options={"pose": start})
    obs_w, _ = wrapped.reset(seed=args.seed, options={"pose": start})
    pose_b = info["pose"]
    images = []
    done = 0
    while done < args.overhead_steps:
        n = min(args.chunk, args.overhead_steps - done)
        for _ in range(n):
            u = pilot_b(pose_b)
            t0 = time.perf_counter()
            _, _, _, _, info = bare.step(u)
            bare_t.append(time.perf_counter() - t0)
            pose_b = info["pose"]
        for _ in range(n):
            u = pilot_w(obs_w["pose_mean"].astype(np.float64))
            t0 = time.perf_counter()
            obs_w, _, _, _, _ = wrapped.step(u)
            wrap_t.append(time.perf_counter() - t0)
            images.append(base.render_camera())
        done += n
    # parts, on the frames of the wrapped drive
    belief = wrapped.belief
    model = belief.model
    f_t, q_t, e_t = [], [], []
    x = belief.x
    for img in images[: min(len(images), 200)]:
        t0 = time.perf_counter()
        w = loc.transform(img)[0]
        t1 = time.perf_counter()
        z = loc.measure(w, measurement)
        model.h(x), model.H(x), model.R_at(x)
        t2 = time.perf_counter()
        f_t.append(t1 - t0)
        q_t.append(t2 - t1)
        if np.all(np.isfinite(z)):
            ekf = belief.ekf
            saved = (ekf.x.copy(), ekf.P.copy())
            t3 = time.perf_counter()
            ekf.predict(np.array([0.5, 0.0]))
            try:
                ekf.update(z, model)
            except ValueError:
                pass
            e_t.append(time.perf_counter() - t3)
            ekf.x, ekf.P = saved
    bare.close()
    env.close()
    ms = lambda v: 1e3 * float(np.median(v)) if len(v) else float("nan")
    return {"env_ms": ms(bare_t), "wrapped_ms": ms(wrap_t),
            "overhead_ms": ms(wrap_t) - ms(bare_t), "features_ms": ms(f_t),
            "gse_query_ms": ms(q_t), "ekf_ms": ms(e_t), "steps": len(wrap_t)}


def dcnn_localizer(env: gym.Env, args: FilterBenchConfig) -> AppearanceLocalizer:
    images, poses = collect_dataset(env, args.n_train_dcnn, "lanes", seed=args.seed,
                                    lanes="route", progress=False)
    loc = AppearanceLocalizer("efficientnet", {"n_components": 64, "progress": False},
                              noise_folds=0)
    loc.fit(images, poses, camera="perspective")
    loc.fit_noise(env.unwrapped.motion_model,
                  *drive_route(env, args.n_drive, seed=args.seed + 1, progress=False))
    return loc


def markdown(result: dict) -> str:
    lines = ["Per-step cost (median ms; overhead = wrapped - bare, same run):", "",
             ("| features | model | bare env | wrapped | overhead | features | GSE query | EKF | "
              "target | |"), "|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in result["overhead"]:
        target = TARGET_MS[r["features"]]
        lines.append(f"| {r['features']} | {r['measurement']} | {r['env_ms']:.2f} | "
                     f"{r['wrapped_ms']:.2f} | {r['overhead_ms']:.2f} | {r['features_ms']:.2f} | "
                     f"{r['gse_query_ms']:.2f} | {r['ekf_ms']:.2f} | <= {target:.0f} | "
                     f"{'PASS' if r['overhead_ms'] <= target else 'MISS'} |")
    lines += ["", f"Tracking ({result['tracking_setup']}):", "",
              ("| model | runs x steps | belief RMSE (m) | dead reckoning RMSE (m) | ratio | "
               "worst run ratio | mean NEES | target | |"),
              "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for name, s in result["tracking"].items():
        lines.append(f"| {name} | {s['runs']} x {s['steps']} | {s['rmse']:.3f} | "
                     f"{s['rmse_dead_reckoning']:.2f} | {s['ratio']:.3f} | {s['worst_ratio']:.3f} "
                     f"| {s['nees_mean']:.2f} | <= {TARGET_RATIO} | "
                     f"{'PASS' if s['ratio'] <= TARGET_RATIO else 'MISS'} |")
    return "\n".join(lines) + "\n"


def run_filter_bench(args: FilterBenchConfig) -> dict:
    """Run the benchmark; write ``bench_filter.json`` / ``.md``; return the result."""
    args = args.resolved()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    env = make_env(args)
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        loc, seconds = fit_city_localizer(env, args.n_train, "route", args.n_drive, args.seed)
        dcnn = None if args.no_dcnn else dcnn_localizer(env, args)
    seconds["fit_total"] = time.perf_counter() - t0
    rows = [{"features": "pixel_pca", "measurement": m, **overhead(args, loc, m)}
            for m in MEASUREMENTS]
    if dcnn is not None:
        rows += [{"features": "efficientnet", "measurement": m, **overhead(args, dcnn, m)}
                 for m in MEASUREMENTS]
    for r in rows:
        print(f"overhead {r['features']:>12} {r['measurement']:>14}: {r['overhead_ms']:.2f} ms "
              f"(bare {r['env_ms']:.2f}, wrapped {r['wrapped_ms']:.2f})", flush=True)
    tracking, runs = {}, []
    path_len = len(PurePursuit(env.unwrapped.city.route()).path)
    starts = [int(i * path_len / args.runs) for i in range(args.runs)]
    for m in MEASUREMENTS:
        ms = [track_metrics(track_route(env, loc, m, args.steps, start=s, seed=args.seed + 50 + i))
              for i, s in enumerate(starts)]
        runs += [{"measurement": m, "start": s, **x} for s, x in zip(starts, ms)]
        rmse = float(np.sqrt(np.mean([x["rmse"] ** 2 for x in ms])))
        rmse_dr = float(np.sqrt(np.mean([x["rmse_dead_reckoning"] ** 2 for x in ms])))
        tracking[m] = {"runs": len(ms), "steps": args.steps, "rmse": rmse,
                       "rmse_dead_reckoning": rmse_dr, "ratio": rmse / rmse_dr,
                       "worst_ratio": max(x["ratio"] for x in ms),
                       "nees_mean": float(np.mean([x["nees_mean"] for x in ms]))}
        print(f"tracking {m:>14}: RMSE {rmse:.3f} m vs dead reckoning {rmse_dr:.2f} m "
              f"(ratio {rmse / rmse_dr:.3f})", flush=True)
    result = {"args": dataclasses.asdict(args), **provenance(),
              "seconds": seconds, "overhead": rows, "tracking": tracking, "runs": runs,
              "tracking_setup": f"city {args.scene_seed}, motion noise {args.motion_noise}, "
                                f"{args.n_train} route-lane images, PixelPCA, starts {starts}"}
    (out / "bench_filter.json").write_text(json.dumps(result, indent=2))
    (out / "bench_filter.md").write_text(markdown(result))
    print(markdown(result))
    env.close()
    return result

