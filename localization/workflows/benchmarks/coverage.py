"""Benchmark of localization anywhere on the street surface at any heading (issue 13,
deliverable 1: ``appearance-nav bench --only coverage``; its options are ``--coverage-<option>``).

    appearance-nav bench --only coverage                  # perspective on cities 41, 42
    appearance-nav bench --only coverage --coverage-quick  # smoke run

Cities ``cities`` (default 41, 42) were never used to choose anything. The features, GSE's
neighbours and the training size were chosen on tuning cities 12 and 13 (64 x 64 perspective,
400 held-out coverage images each; median position error):

- features, 20000 images: PixelPCA(64) on the upper 55 % of the rows 1.36 / 0.75 m (cities
  12 / 13); the packaged SmallCNN of the camera (trained pose-contrastively on random views of
  cities 100-119, ``small_cnn_<camera>_random.pt``) on the whole image, PCA 64: 0.29 / 0.30 m;
  on the upper rows only 0.45 m (city 12); PCA 32 0.28 m and the raw 128-d embedding 0.30 m
  (city 12), no clear gain;
- GSE neighbours on the SmallCNN features (``SMALL_CNN_NEIGHBORS``): 6 / 10 / 15 / 20 / 30
  gave 0.28 / 0.29 / 0.25 / 0.26 / 0.28 m on city 12 and 10 / 15 / 20 gave 0.30 / 0.28 /
  0.29 m on city 13;
- size (city 12, SmallCNN): 20000 0.29 m, 40000 0.21 m (10 neighbours), 80000 0.16 m, 100000
  0.13 m (15 neighbours; the fit 177 s, the whole run's peak memory 5.1 GB), still falling;
  the refined estimate (``predict(refine=3)``) 71.2 / 88.2 % within (0.25 m, 2 deg) /
  (0.5 m, 5 deg) at 100000 and 75.8 / 91.2 % at 200000 (stop 34): the default is 200000.

The corner weight of the coverage poses was chosen on city 13 (docs/method.md §12). Per city
and camera one localizer is fitted on ``n_train`` images over the whole street surface at
every heading (``collect_dataset(mode="coverage")``, :mod:`envs.coverage`), and its noise
model on off-lane drives (:func:`~localization.workflows.tracking.fit_city_noise` with
``lanes="free"``).

* single image (the format of Aachen Day-Night): ``n_test`` new coverage poses per city
  (another seed); the share of images whose pose estimate is within (0.25 m, 2 deg),
  (0.5 m, 5 deg) and (5 m, 10 deg) of the truth, median position and heading errors, for
  GSE (the localizer's psi*), KNR (:class:`~localization.baselines.KernelRegressor`, one LOO
  bandwidth) and kNN retrieval (:class:`~localization.baselines.RetrievalRegressor`, k by
  CV) on the same features of the same training images (an image outside the domain counts
  as a miss);
* closed loop: ``n_drives`` off-lane drives of ``drive_steps`` steps per city
  (:func:`~localization.workflows.tracking.track_off_lane`: weaving, U-turns, turning on the
  spot at corners, starts off the lanes at a random heading), "representation" model: belief
  RMSE pooled over the drives, its ratio to dead reckoning's on the same controls, mean of
  the run-averaged NEES against its 95 % chi-square band. With ``lane_baseline`` a localizer
  fitted on every street's lanes (the same n) drives the same drives, for comparison.

Targets (issue 13): GSE median position error <= 0.15 m, >= 75 % within (0.25 m, 2 deg),
>= 90 % within (0.5 m, 5 deg), ahead of KNR and retrieval; closed loop RMSE <= 0.15 m and
<= 0.05 x dead reckoning, NEES in the band.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np
from tqdm import tqdm

from envs.datasets import collect_dataset
from localization.baselines import KernelRegressor, RetrievalRegressor
from localization.geometry import wrap_angle
from localization.localizer import AppearanceLocalizer, city_info
from localization.workflows.benchmarks.coverage_report import THRESHOLDS, markdown
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.benchmarks.street_features import (
    features_label,
    localizer_features,
)
from localization.workflows.tracking import (
    distinct_views,
    fit_city_localizer,
    fit_city_noise,
    nees_band,
    track_metrics,
    track_off_lane,
)

__all__ = ["SMALL_CNN_NEIGHBORS", "CoverageBenchConfig", "localizer_params", "run_coverage_bench",
           "single_image_errors"]

METHODS = ("GSE", "GSE refined", "KNR", "retrieval")
#: GSE neighbours on the SmallCNN features (tuning cities 12, 13: docs/benchmarks.md §6)
SMALL_CNN_NEIGHBORS = 15


@dataclass
class CoverageBenchConfig:
    """Settings of the coverage benchmark."""

    cities: str = field(default="41,42", metadata={
        "help": "comma-separated scene seeds (never used to tune anything)"})
    cameras: str = field(default="perspective", metadata={
        "help": "comma-separated cameras (perspective, fisheye, catadioptric)"})
    image_size: int = field(default=64, metadata={"help": "square image side (px)"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    n_train: int = field(default=200_000, metadata={
        "help": "coverage training images per city and camera"})
    features: str = field(default="small_cnn", metadata={
        "help": "small_cnn (the packaged SmallCNN of the camera, trained pose-contrastively on "
                "random views of cities 100-119, on the whole image) or pixel_pca (PixelPCA on "
                "the localizer's upper image rows)"})
    n_components: int = field(default=64, metadata={
        "help": "PCA components of the features"})
    n_drive: int = field(default=1500, metadata={"help": "steps of each noise-calibration drive"})
    n_test: int = field(default=500, metadata={"help": "single test images per city and camera"})
    refine: int = field(default=3, metadata={
        "help": "Gauss-Newton steps of the 'GSE refined' row (predict(refine=...); 3 chosen "
                "on tuning cities 12-13)"})
    n_drives: int = field(default=3, metadata={"help": "off-lane drives per city and camera"})
    drive_steps: int = field(default=500, metadata={"help": "steps of each off-lane drive"})
    lane_baseline: bool = field(default=False, metadata={
        "help": "also drive the off-lane drives on a localizer fitted on every street's lanes"})
    quick: bool = field(default=False, metadata={"help": "smoke run: one city, tiny fits"})
    seed: int = field(default=0, metadata={"help": "seed of fits, test poses and drives"})
    out_dir: str = field(default="results", metadata={"help": "where bench_coverage.json/.md go"})

    def resolved(self) -> CoverageBenchConfig:
        """The settings actually run (``quick``: one city, small fits)."""
        if not self.quick:
            return self
        return dataclasses.replace(
            self, cities=self.cities.split(",")[0], cameras=self.cameras.split(",")[0],
            image_size=32, n_train=600, n_components=8, n_drive=250, n_test=40, n_drives=1,
            drive_steps=40)

    def lists(self) -> tuple[list[int], list[str]]:
        """(cities, cameras) as lists."""
        return ([int(s) for s in self.cities.split(",")],
                [s.strip() for s in self.cameras.split(",")])


def make_env(args: CoverageBenchConfig, city: int, camera: str) -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, camera=camera,
                    image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def localizer_params(args: CoverageBenchConfig, camera: str) -> dict[str, Any]:
    """The :class:`AppearanceLocalizer` feature settings of ``args.features`` on ``camera``
    (the SmallCNN with ``SMALL_CNN_NEIGHBORS`` GSE neighbours)."""
    params = localizer_features(args.features, camera, args.n_components)
    if args.features == "small_cnn":
        params["regressor_params"] = {"n_neighbors": SMALL_CNN_NEIGHBORS}
    return params


def single_image_errors(pred: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (m) and heading (deg) errors (n,) of pose estimates (n, 3); inf where an
    estimate is not finite (outside the training domain)."""
    pos = np.hypot(*(pred[:, :2] - poses[:, :2]).T)
    yaw = np.degrees(np.abs(wrap_angle(pred[:, 2] - poses[:, 2])))
    bad = ~np.isfinite(pred).all(axis=1)
    pos[bad], yaw[bad] = np.inf, np.inf
    return pos, yaw


@contextmanager
def quiet() -> Iterator[None]:
    """Ignore GSE's eigen-gap warnings and the quality warning inside (reported instead)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        warnings.filterwarnings("ignore", message=".*quality.*")
        yield


def fit_city(args: CoverageBenchConfig, env: gym.Env
             ) -> tuple[AppearanceLocalizer, dict[str, Any], dict[str, float]]:
    """The coverage localizer of the env's city, KNR and retrieval on its features, and
    the seconds of each stage."""
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    images, poses = collect_dataset(env, args.n_train, "coverage", seed=args.seed,
                                    progress=False)
    seconds["collect"] = time.perf_counter() - t0
    with quiet():
        t0 = time.perf_counter()
        loc = AppearanceLocalizer(noise_folds=0,
                                  **localizer_params(args, env.unwrapped.camera_name))
        images, poses = distinct_views(loc, images, poses)
        loc.fit(images, poses, camera=env.unwrapped.camera_name, city=city_info(env))
        seconds["fit GSE"] = time.perf_counter() - t0
        W = loc.transform(images)
        baselines: dict[str, Any] = {}
        for name, est in (("KNR", KernelRegressor(periodic=(2,))),
                          ("retrieval", RetrievalRegressor(n_neighbors="cv", periodic=(2,),
                                                           random_state=args.seed))):
            t0 = time.perf_counter()
            baselines[name] = est.fit(W, poses)
            seconds[f"fit {name}"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        fit_city_noise(env, loc, "free", args.n_drive, args.seed, calibrate_on_belief=True,
                       measurements=("representation",))
        seconds["noise"] = time.perf_counter() - t0
    return loc, baselines, seconds


def lane_localizer(args: CoverageBenchConfig, env: gym.Env) -> AppearanceLocalizer:
    """The comparison: the same fit on every street's lanes (lane drives for the noise)."""
    with quiet():
        loc, _ = fit_city_localizer(
            env, n_train=args.n_train, lanes="streets", n_drive=args.n_drive, seed=args.seed,
            localizer_params=localizer_params(args, env.unwrapped.camera_name),
            measurements=("representation",), quality_steps=0)
    return loc


def drives(args: CoverageBenchConfig, env: gym.Env, loc: AppearanceLocalizer, base: int
           ) -> list[dict[str, float]]:
    """The off-lane drives of one city on ``loc`` (seeds ``base + k``)."""
    with quiet():
        return [track_metrics(track_off_lane(env, loc, "representation", args.drive_steps,
                                             seed=base + k)) for k in range(args.n_drives)]


def summarize_single(errors: list[tuple[np.ndarray, np.ndarray]]) -> dict[str, Any]:
    pos = np.concatenate([e[0] for e in errors])
    yaw = np.concatenate([e[1] for e in errors])
    return {"n_images": len(pos),
            "within": [float(np.mean((pos <= m) & (yaw <= d))) for m, d in THRESHOLDS],
            "median_pos_err": float(np.median(pos)), "median_yaw_err_deg": float(np.median(yaw)),
            "out_of_domain": float(np.mean(~np.isfinite(pos)))}


def summarize_drives(runs: list[dict[str, float]]) -> dict[str, Any]:
    sq = sum(r["rmse"] ** 2 * (r["steps"] + 1) for r in runs)
    sq_dr = sum(r["rmse_dead_reckoning"] ** 2 * (r["steps"] + 1) for r in runs)
    n = sum(r["steps"] + 1 for r in runs)
    lo, hi = nees_band(len(runs))
    rmse, rmse_dr = float(np.sqrt(sq / n)), float(np.sqrt(sq_dr / n))
    return {"drives": len(runs), "rmse": rmse, "rmse_dead_reckoning": rmse_dr,
            "ratio": rmse / rmse_dr if rmse_dr > 0 else float("nan"),
            "max_error": float(max(r["max_error"] for r in runs)),
            "nees_mean": float(np.mean([r["nees_mean"] for r in runs])), "nees_band": [lo, hi],
            "accepted": float(np.mean([r["accepted"] for r in runs])),
            "distance": float(np.mean([r["distance"] for r in runs]))}


def _result(args: CoverageBenchConfig, done: list[int], cameras: list[str],
            single: dict[str, dict[str, list[Any]]], loop: dict[str, dict[str, list[Any]]],
            seconds: list[dict[str, Any]], t0: float) -> dict[str, Any]:
    """The JSON result of the cities ``done`` so far."""
    summary = {c: {"single": {m: summarize_single(single[c][m]) for m in METHODS},
                   "closed_loop": {k: summarize_drives(v) for k, v in loop[c].items() if v}}
               for c in cameras if all(single[c].values())}
    return {"args": dataclasses.asdict(args), **provenance(),
            "seconds": time.perf_counter() - t0, "stage_seconds": seconds,
            "thresholds": THRESHOLDS, "cameras": list(summary), "summary": summary,
            "drives": loop,
            "setup": f"cities {','.join(map(str, done))}, {args.image_size}x{args.image_size} "
                     f"images, motion noise {args.motion_noise}, "
                     f"{features_label(args.features, args.n_components)} on {args.n_train} "
                     f"coverage images per city; {args.n_test} test images "
                     f"and {args.n_drives} off-lane drive(s) of {args.drive_steps} steps "
                     f"per city"}


def run_coverage_bench(args: CoverageBenchConfig) -> dict[str, Any]:
    """Run the benchmark; write ``bench_coverage.json`` / ``.md``; return the result."""
    args = args.resolved()
    cities, cameras = args.lists()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    single = {c: {m: [] for m in METHODS} for c in cameras}
    loop: dict[str, dict[str, list[dict[str, float]]]] = {c: {"coverage": [], "lanes": []}
                                                          for c in cameras}
    seconds: list[dict[str, Any]] = []
    failures: list[str] = []
    with tqdm(total=len(cities) * len(cameras), desc="bench coverage", leave=False) as bar:
        for i, city in enumerate(cities):
            base = args.seed + 10_000 * (i + 1)
            for camera in cameras:
                env = make_env(args, city, camera)
                try:
                    loc, baselines, sec = fit_city(args, env)
                except ValueError as err:  # e.g. GSE's graph leaves a sample on its own
                    failures.append(f"city {city}, {camera}: {err}")
                    env.close()
                    bar.update()
                    continue
                seconds.append({"city": city, "camera": camera, **sec})
                images, poses = collect_dataset(env, args.n_test, "coverage", seed=base,
                                                progress=False)
                W = loc.transform(images)
                preds = {"GSE": loc.predict(images),
                         "GSE refined": loc.predict(images, refine=args.refine),
                         **{k: est.predict(W) for k, est in baselines.items()}}
                for m in METHODS:
                    single[camera][m].append(single_image_errors(preds[m], poses))
                loop[camera]["coverage"] += drives(args, env, loc, base + 100)
                if args.lane_baseline:
                    lanes = lane_localizer(args, env)
                    loop[camera]["lanes"] += drives(args, env, lanes, base + 100)
                env.close()
                bar.update()
                done = cities[: i + 1]  # written after every city: a long run keeps its part
                result = _result(args, done, cameras, single, loop, seconds, t0)
                result["fit_failures"] = failures
                (out / "bench_coverage.json").write_text(json.dumps(result, indent=2))
                (out / "bench_coverage.md").write_text(markdown(result))
    result = _result(args, cities, cameras, single, loop, seconds, t0)
    result["fit_failures"] = failures
    (out / "bench_coverage.json").write_text(json.dumps(result, indent=2))
    (out / "bench_coverage.md").write_text(markdown(result))
    print(markdown(result))
    return result
