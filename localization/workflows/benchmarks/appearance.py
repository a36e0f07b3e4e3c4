"""Benchmark of localization under appearance change (issue 14): lighting, weather, camera
effects and moving things (``appearance-nav bench --only appearance``; its options are
``--appearance-<option>``).

    appearance-nav bench --only appearance                   # ~6 CPU-minutes, 10.5 min at load 3-7
    appearance-nav bench --only appearance --appearance-quick  # smoke run

Cities ``cities`` (default 31, 32) were never used to tune anything (the presets were looked
at on city 0; :mod:`.global_loc` uses 21-24). On each city two localizers are fitted as the
tracking test fits its held-out city (:func:`~localization.workflows.tracking.fit_city_localizer`
around the route's lanes, 64 x 64 images, PixelPCA; ``lanes="streets"`` fits street-wide
ones as :mod:`.global_loc` does): "daylight" on the default look only, "randomised" with
one map per look (``randomised_map="experiences"``: daylight and a draw of each other lighting
family, :func:`envs.conditions.experience_looks`) and its noise drives under
``conditions="random"`` (one look each). The settings are
:class:`~.appearance_config.AppearanceBenchConfig`. The test conditions are the presets themselves, never used to
choose anything.

Per condition (the format of the visual-localization benchmarks, Aachen Day-Night and
RobotCar Seasons):

* single image: ``n_test`` lane poses per city (the same poses under every condition);
  the share of images whose psi* pose is within (0.25 m, 2 deg), (0.5 m, 5 deg) and
  (5 m, 10 deg) of the truth (an image outside the training domain counts as a miss);
* closed loop: ``n_drives`` drives of ``drive_steps`` steps per city on the belief (around the
  route from path points 0, 600, ...: :func:`~localization.workflows.tracking.track_route`; or
  street tours), "representation" model; position
  RMSE over all drives, its ratio to the default look's RMSE on the same drives, and the
  mean over drives of the run-averaged NEES against its 95 % chi-square band;
* moving objects (conditions with vehicles or pedestrians): the share of frames in which a
  mover covers any pixel (a segmentation render), and the largest belief jump on such a
  frame: ``|(m_t - m_{t-1}) - (x_t - x_{t-1})|`` (belief mean m, truth x, metres).

Targets (issue 14): daylight localizer: dusk and overcast >= 75/90/99 %, night >= 50/75/95 %;
randomised localizer: every preset >= 80/92/99 % and default no worse than the daylight
localizer's; closed loop: RMSE <= 2x default, NEES in band; moving objects: RMSE <= 1.5x
default (with movers in >= 30 % of frames), no jump above 1 m on an occluded frame.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import mujoco
import numpy as np
from tqdm import tqdm

from envs.conditions import CAMERAS, experience_looks
from envs.datasets import collect_dataset
from localization._validation import check_choice
from localization.filtering.belief import NOISE_MODELS
from localization.geometry import wrap_angle
from localization.workflows.benchmarks.appearance_config import (
    FEATURES,
    MAP_CAMERAS,
    RANDOMISED_MAPS,
    TRAININGS,
    AppearanceBenchConfig,
)
from localization.workflows.benchmarks.appearance_report import map_images_label, markdown
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.tracking import (
    fit_city_localizer,
    nees_band,
    track_route,
    track_streets,
)

__all__ = ["FEATURES", "MAP_CAMERAS", "RANDOMISED_MAPS", "THRESHOLDS", "AppearanceBenchConfig", "OcclusionRecorder",
           "fit_looks", "map_conditions", "run_appearance_bench", "training_looks"]

#: (metres, degrees) of the visual-localization benchmarks
THRESHOLDS = ((0.25, 2.0), (0.5, 5.0), (5.0, 10.0))


def training_looks(training: str, randomised_map: str) -> tuple[str, str]:
    """(conditions of the map images, conditions of the noise and calibration drives) of the
    localizer ``training`` ("daylight" or "randomised"); the randomised one's map images in
    ``randomised_map`` (one of :data:`RANDOMISED_MAPS`)."""
    looks = TRAININGS[training]
    return (randomised_map if training == "randomised" else looks), looks


def map_conditions(map_looks: str, city: int, camera: str = "look") -> list[Any]:
    """Conditions of the map's envs: ``[map_looks]``, or for "experiences" today's daylight
    and one draw of each other lighting family of the randomisation
    (:func:`envs.conditions.experience_looks`, seeded by the city): an
    :class:`~localization.experiences.ExperienceLocalizer`. ``camera="random"``: each
    look's images through randomised camera effects (every image its own draw,
    ``{"preset": look, "camera": "random"}``) instead of the look's own."""
    check_choice(camera, "camera", CAMERAS)
    looks = list(experience_looks(city)) if map_looks == "experiences" else [map_looks]
    return looks if camera == "look" else [{"preset": c, "camera": "random"} for c in looks]


def fit_looks(make: Any, city: int, map_looks: str, looks: str,
              calibrate_on_belief: bool = False, map_camera: str = "look", **fit: Any) -> Any:
    """:func:`fit_city_localizer` of ``city`` with its map in ``map_looks``
    (:func:`map_conditions`, its images' camera ``map_camera``) and its noise and
    calibration drives in ``looks`` (the consistency refined on a drive on the belief if
    ``calibrate_on_belief``); ``make(c)`` makes the city's env in conditions c; the envs are
    closed after."""
    maps = [make(c) for c in map_conditions(map_looks, city, map_camera)]
    noise_env = maps[0] if map_looks == looks else make(looks)
    try:
        with warnings.catch_warnings():  # GSE's eigen-gap warning on thin tubes of poses
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            warnings.filterwarnings("ignore", message=".*quality.*")
            loc, _ = fit_city_localizer(maps[0], noise_env=noise_env, experience_envs=maps[1:],
                                        calibrate_on_belief=calibrate_on_belief,
                                        measurements=("representation",), quality_steps=0,
                                        **fit)
    finally:
        for env in {id(e): e for e in [*maps, noise_env]}.values():
            env.close()
    return loc


class OcclusionRecorder(gym.Wrapper):
    """Records, at every reset and step, the share of the ego camera's pixels that show a
    moving object (a segmentation render of the same state) in :attr:`shares`."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        base = env.unwrapped
        self._renderer = mujoco.Renderer(base.model, *base.image_size)
        self._renderer.enable_segmentation_rendering()
        self._movers = base.traffic.geom_ids if base.traffic is not None else np.zeros(0, int)
        self.shares: list[float] = []

    def _record(self) -> None:
        if not len(self._movers):
            self.shares.append(0.0)
            return
        self._renderer.update_scene(self.env.unwrapped.data, camera="ego")
        seg = self._renderer.render()
        hit = (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & np.isin(seg[..., 0], self._movers)
        self.shares.append(float(hit.mean()))

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        out = self.env.reset(**kwargs)
        self.shares = []
        self._record()
        return out

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        out = self.env.step(action)
        self._record()
        return out

    def close(self) -> None:
        self._renderer.close()
        super().close()


def make_env(args: AppearanceBenchConfig, city: int, conditions: Any) -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, conditions=conditions,
                    image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def smooths(args: AppearanceBenchConfig, training: str) -> bool:
    """Whether the PixelPCA of the localizer ``training`` blurs its images (``args.smooth``)."""
    return args.smooth > 0 and training in [t.strip() for t in args.smooth_trainings.split(",")]


def localizer_params(args: AppearanceBenchConfig, training: str = "daylight") -> dict[str, Any]:
    """The :class:`AppearanceLocalizer` feature settings of ``args.features`` for the
    localizer ``training``."""
    if args.features == "small_cnn":
        from localization.features.weights import small_cnn_weights

        weights = small_cnn_weights("perspective", "conditions")
        return {"features": "small_cnn",
                "features_params": {"n_components": args.n_components, "weights": str(weights)},
                "regressor_params": regressor_params(args), **noise_params(args, training)}
    params: dict[str, Any] = {"n_components": args.n_components}
    if args.normalize != "none":
        params["normalize"] = args.normalize
    if args.normalize == "patches":
        params["patch_floor"] = args.patch_floor
    if smooths(args, training):
        params["smooth"] = args.smooth
    return {"features_params": params, "regressor_params": regressor_params(args),
            **noise_params(args, training)}


def noise_params(args: AppearanceBenchConfig, training: str = "daylight") -> dict[str, Any]:
    """``noise_folds`` of the localizer ``training``: 5 for a heteroscedastic R
    (:meth:`AppearanceBenchConfig.noise_of`)."""
    check_choice(args.noise, "noise", NOISE_MODELS)
    return {"noise_folds": 5} if args.noise_of(training)[0] == "heteroscedastic" else {}


def noise_label(noise: str, adaptive: bool, bias: bool) -> str:
    """A closed loop's noise model in the report's words."""
    return (f"{noise} R" + (" scaled by the innovations" if adaptive else "")
            + (" with a persistent bias state" if bias else ""))


def regressor_params(args: AppearanceBenchConfig) -> dict[str, Any]:
    """The :class:`GSERegressor` settings of the benchmark's localizers."""
    out: dict[str, Any] = {"first_order": args.first_order}
    if args.first_order == "forward":
        out["forward_ridge"] = args.forward_ridge
    return out


def features_label(args: AppearanceBenchConfig) -> str:
    """The feature extractor in the report's words."""
    if args.features == "small_cnn":
        return f"SmallCNN (condition-randomised, other cities; PCA {args.n_components})"
    smooth = ""
    if args.smooth > 0:
        smooth = f", smooth={args.smooth:g} ({args.smooth_trainings.replace(',', ', ')})"
    if args.normalize == "patches":
        return (f"PixelPCA({args.n_components}, normalize={args.normalize}, "
                f"patch_floor={args.patch_floor:g}{smooth})")
    return f"PixelPCA({args.n_components}, normalize={args.normalize}{smooth})"


def fit(args: AppearanceBenchConfig, city: int, training: str) -> Any:
    """The localizer ``training`` ("daylight" or "randomised") of ``city``: its noise and
    calibration drives in the training's look, its map images too (the randomised one's
    in ``args.randomised_map``)."""
    map_looks, looks = training_looks(training, args.randomised_map)
    camera = args.map_camera if training == "randomised" else "look"
    return fit_looks(lambda c: make_env(args, city, c), city, map_looks, looks,
                     args.calibrate_on_belief, camera, n_train=args.n_train, lanes=args.lanes,
                     n_drive=args.n_drive, seed=args.seed,
                     localizer_params=localizer_params(args, training))


def single_image_scores(loc: Any, images: np.ndarray, poses: np.ndarray, verify: int = 0,
                        verify_margin: float = 3.0, turns: int = 0) -> dict[str, Any]:
    """Position (m) and heading (deg) errors of psi* per image (inf outside the domain;
    ``verify`` > 0: checked against that many retrieved training poses; ``turns`` > 0: the
    position the median over turned views, :meth:`AppearanceLocalizer.predict`) and the
    share within each of :data:`THRESHOLDS`."""
    pred = loc.predict(images, verify=verify, verify_margin=verify_margin, turns=turns)
    pos = np.hypot(*(pred[:, :2] - poses[:, :2]).T)
    yaw = np.degrees(np.abs(wrap_angle(pred[:, 2] - poses[:, 2])))
    bad = ~np.isfinite(pred).all(axis=1)
    pos[bad], yaw[bad] = np.inf, np.inf
    return {"pos_err": pos.tolist(), "yaw_err_deg": yaw.tolist(),
            "within": [float(np.mean((pos <= m) & (yaw <= d))) for m, d in THRESHOLDS]}


def closed_loop(env: OcclusionRecorder, loc: Any, lanes: str, steps: int, k: int, seed: int,
                noise: str = "global", adaptive: bool = False, bias: bool = False,
                familiar: float = 0.0, novelty: bool = False) -> dict[str, Any]:
    """Drive ``k`` on the belief (around the route from path point ``600 k``, or a random
    street tour; measurement noise ``noise``, scaled by the innovations if ``adaptive``,
    with a persistent bias state if ``bias``, (re)starts only from images of relative
    novelty <= ``familiar`` if > 0, R scaled by the image's novelty if ``novelty``): squared
    errors, run-averaged NEES, occlusion, jumps."""
    options = {"filter_options": {"noise": noise, "adaptive_noise": adaptive,
                                  "measurement_bias": bias, "novelty_noise": novelty}}
    if familiar > 0:
        options["filter_options"]["familiar_novelty"] = familiar
    if lanes == "route":
        run = track_route(env, loc, "representation", steps, start=600 * k, seed=seed,
                          **options)
    else:
        run = track_streets(env, loc, "representation", steps, seed=seed, **options)
    err2 = np.sum((run.mean[:, :2] - run.true[:, :2]) ** 2, axis=1)
    shares = np.asarray(env.shares)
    step = np.hypot(*(np.diff(run.mean[:, :2], axis=0) - np.diff(run.true[:, :2], axis=0)).T)
    occluded = shares[1:] > 0
    return {"sse": float(err2.sum()), "n": len(err2), "nees_mean": float(np.mean(run.nees)),
            "occluded_frames": float(np.mean(shares > 0)),
            "occluded_pixels": float(np.mean(shares)),
            "max_jump_occluded": float(step[occluded].max()) if occluded.any() else 0.0,
            "accepted": float(np.mean(np.array(run.status[1:]) == "accepted"))}


def summarize(single: list[dict[str, Any]], drives: list[dict[str, Any]]) -> dict[str, Any]:
    """Pooled scores of one (training, condition) over the cities."""
    pos = np.concatenate([s["pos_err"] for s in single])
    yaw = np.concatenate([s["yaw_err_deg"] for s in single])
    lo, hi = nees_band(len(drives))
    return {"n_images": len(pos),
            "within": [float(np.mean((pos <= m) & (yaw <= d))) for m, d in THRESHOLDS],
            "median_pos_err": float(np.median(pos)),
            "drives": len(drives),
            "rmse": float(np.sqrt(sum(d["sse"] for d in drives) / sum(d["n"] for d in drives))),
            "nees_mean": float(np.mean([d["nees_mean"] for d in drives])),
            "nees_band": [lo, hi],
            "accepted": float(np.mean([d["accepted"] for d in drives])),
            "occluded_frames": float(np.mean([d["occluded_frames"] for d in drives])),
            "occluded_pixels": float(np.mean([d["occluded_pixels"] for d in drives])),
            "max_jump_occluded": float(max(d["max_jump_occluded"] for d in drives))}


def run_appearance_bench(args: AppearanceBenchConfig) -> dict[str, Any]:
    """Run the benchmark; write ``bench_appearance.json`` / ``.md``; return the result."""
    args = args.resolved()
    cities, conditions, trainings = args.lists()
    novel = args.novelty_trainings()
    args.noise_of("daylight")  # a misspelt noise_trainings fails here, before any fit
    bad = [t for t in trainings if t not in TRAININGS]
    if bad:
        raise ValueError(f"trainings: unknown {bad}; choose from {list(TRAININGS)}")
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    single = {t: {c: [] for c in conditions} for t in trainings}
    drives = {t: {c: [] for c in conditions} for t in trainings}
    fit_seconds: list[float] = []
    failures: dict[str, list[str]] = {}
    work = len(cities) * (len(trainings) + len(conditions))
    with tqdm(total=work, desc="bench appearance", leave=False) as bar:
        for i, city in enumerate(cities):
            locs = {}
            for t in trainings:
                t1 = time.perf_counter()
                try:
                    locs[t] = fit(args, city, t)
                except ValueError as err:  # e.g. GSE's graph falls apart on mixed looks
                    failures.setdefault(t, []).append(f"city {city}: {err}")
                fit_seconds.append(time.perf_counter() - t1)
                bar.update()
            base = args.seed + 10_000 * (i + 1)
            for c in conditions:
                env = OcclusionRecorder(make_env(args, city, c))
                images, poses = collect_dataset(env, args.n_test, "lanes", seed=base,
                                                progress=False, lanes=args.lanes)
                for t, loc in locs.items():
                    single[t][c].append(single_image_scores(loc, images, poses, args.verify,
                                                             args.verify_margin, args.turns))
                    for k in range(args.n_drives):
                        drives[t][c].append(closed_loop(env, loc, args.lanes,
                                                        args.drive_steps, k, base + 100 + k,
                                                        *args.noise_of(t),
                                                        args.familiar_novelty,
                                                        t in novel))
                env.close()
                bar.update()
    summary = {t: {c: summarize(single[t][c], drives[t][c]) if drives[t][c] else None
                   for c in conditions} for t in trainings}
    result = {"args": dataclasses.asdict(args), **provenance(),
              "seconds": time.perf_counter() - t0, "fit_seconds": fit_seconds,
              "thresholds": THRESHOLDS, "trainings": trainings, "conditions": conditions,
              "summary": summary, "drives": drives, "fit_failures": failures,
              "setup": f"cities {args.cities}, {args.lanes} lanes, "
                       f"{args.image_size}x{args.image_size} images, "
                       f"motion noise {args.motion_noise}, {features_label(args)} "
                       f"on {args.n_train} lane images per city (the randomised "
                       f"localizer: {map_images_label(args.randomised_map)}"
                       + (", each map image through its own random camera"
                          if args.map_camera == "random" else "") + "); "
                       f"{args.n_test} test images and {args.n_drives} drive(s) of "
                       f"{args.drive_steps} steps per city and condition, "
                       + "; ".join(f"{t}: {noise_label(*args.noise_of(t))}" for t in trainings)
                       + (f", scaled by the image's novelty ({', '.join(novel)})"
                          if novel else "")
                       + (f", (re)starts only from images of novelty <= "
                          f"{args.familiar_novelty:g}" if args.familiar_novelty else "")
                       + (f"; single images verified against {args.verify} retrieved "
                          f"poses (margin {args.verify_margin})" if args.verify else "")
                       + (f"; positions the median over views turned by up to {args.turns} "
                          "pixels" if args.turns else "")}
    (out / "bench_appearance.json").write_text(json.dumps(result, indent=2))
    (out / "bench_appearance.md").write_text(markdown(result))
    print(markdown(result))
    return result
