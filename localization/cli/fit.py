"""Fit an AppearanceLocalizer on recorded images and poses, or on a simulated city, and save it.

Recorded data (``--data``): a folder of PNG/JPEG images with a TUM pose file
(``poses.txt`` or ``groundtruth.txt`` in the folder, or ``--pose-file``; lines
``timestamp tx ty tz qx qy qz qw``, the planar pose [x, y, yaw] taken from them), matched to
the images by the timestamps in their file names (or in order), or a ``.npz`` dataset of
``appearance-nav collect``. See ``localization.recorded`` for the formats.

    appearance-nav fit --data recordings/run1 --resize 48x64 --out results/run1.npz
    appearance-nav fit --data data/route.npz --features pixel_pca --n-components 32

The measurement noise then comes from K-fold refits (``--noise-folds``). Without ``--data``
the localizer is fitted on a simulated city (lane images, then noise drives and the
filter's calibration, as ``appearance-nav track`` does):

    appearance-nav fit --scene-seed 0 --n-train 6000 --out results/localizer.npz

A large city gets one localizer per district (``--districts 3``: 3 x 3, a
``DistrictLocalizer`` in the same kind of file; docs/method.md §12.1):

    appearance-nav fit --city-size 60 --lanes streets --n-train 48000 --districts 3
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from localization.cli._args import UsageError, check_env
from localization.cli._recorded import check_data_options, check_out, load_data
from localization.features import FEATURE_NAMES
from localization.recorded import MAX_DIFFERENCE

LANES = ("route", "streets")
MIN_DRIVE = 200  # steps: 4 x the block of filtering.measurement_noise.correlation_time


@dataclass
class Args:
    data: str = field(default="", metadata={
        "help": "recorded data: a folder of images with a TUM pose file, or a .npz; "
                "empty: fit on a simulated city"})
    pose_file: str = field(default="", metadata={
        "help": "TUM pose file of a folder (default: its poses.txt or groundtruth.txt)"})
    match: str = field(default="auto", metadata={
        "help": "images to poses: 'timestamp' (file names), 'order', or 'auto'"})
    max_difference: float = field(default=MAX_DIFFERENCE, metadata={
        "help": "largest time (s) between an image and its pose"})
    resize: str = field(default="", metadata={
        "help": "resize the folder's images to HEIGHTxWIDTH (e.g. 48x64)"})
    features: str = field(default="pixel_pca", metadata={
        "help": "feature extractor: " + ", ".join(FEATURE_NAMES)})
    n_components: int = field(default=0, metadata={
        "help": "feature dimension (0: the extractor's default)"})
    n_neighbors: int = field(default=0, metadata={
        "help": "neighbours of the GSE regression (0: the localizer's default)"})
    noise_folds: int = field(default=3, metadata={
        "help": "folds of the measurement-noise estimate on recorded data (0: none)"})
    scene_seed: int = field(default=0, metadata={"help": "simulated city: names the city"})
    city_size: float = field(default=20.0, metadata={
        "help": "simulated city: its side (m; 60: nine times the default area)"})
    camera: str = field(default="perspective", metadata={"help": "simulated city: camera"})
    image_size: int = field(default=64, metadata={
        "help": "simulated city: side of the square camera image"})
    motion_noise: float = field(default=0.05, metadata={
        "help": "simulated city: actuation noise of the noise drives"})
    lanes: str = field(default="route", metadata={
        "help": "simulated city: training lanes, 'route' or 'streets'"})
    n_train: int = field(default=6000, metadata={"help": "simulated city: training images"})
    n_drive: int = field(default=1000, metadata={
        "help": "simulated city: steps of each noise drive"})
    districts: int = field(default=1, metadata={
        "help": "simulated city: a DistrictLocalizer of N x N districts (large cities; 1: one "
                "map)"})
    overlap: float = field(default=4.0, metadata={
        "help": "simulated city: metres of images neighbouring districts share"})
    seed: int = field(default=0, metadata={"help": "seed of the fit (and of the city's drives)"})
    out: str = field(default="results/localizer.npz", metadata={
        "help": "the saved localizer (.npz; its folder is created)"})


def localizer_params(args: Args) -> dict[str, Any]:
    """Keyword arguments of AppearanceLocalizer from the options (only those given)."""
    if args.features not in FEATURE_NAMES:
        raise UsageError("features", f"must be one of {', '.join(FEATURE_NAMES)}, "
                         f"got {args.features!r}")
    for name in ("n_components", "n_neighbors", "noise_folds"):
        if getattr(args, name) < 0:
            raise UsageError(name, f"must be >= 0, got {getattr(args, name)}")
    params: dict[str, Any] = {"features": args.features, "random_state": args.seed}
    if args.n_components:
        params["features_params"] = {"n_components": args.n_components}
    if args.n_neighbors:
        params["regressor_params"] = {"n_neighbors": args.n_neighbors}
    return params


def fit_recorded(args: Args, out: Path) -> None:
    """Fit on ``args.data`` and save to ``out``."""
    from localization.localizer import AppearanceLocalizer

    check_data_options(args.data, args.pose_file, args.match, args.resize)
    if args.noise_folds == 1:
        raise UsageError("noise-folds", "must be 0 or >= 2, got 1")
    params = {**localizer_params(args), "noise_folds": args.noise_folds}
    rec = load_data(args.data, args.pose_file, args.match, args.resize, args.max_difference,
                    require_poses=True)
    t0 = time.perf_counter()
    loc = AppearanceLocalizer(**params).fit(rec.images, rec.poses)
    print(f"fitted on {len(rec.images)} images in {time.perf_counter() - t0:.1f} s")
    if "pose" in loc.residual_rms_:
        along, cross, yaw = loc.residual_rms_["pose"]
        print(f"held-out pose residual RMS ({args.noise_folds} folds): along {along:.3f} m, "
              f"across {cross:.3f} m, heading {yaw:.3f} rad")
    loc.save(out)


def fit_city(args: Args, out: Path) -> None:
    """Fit on the simulated city of ``args`` and save to ``out``."""
    import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

    # isort: split
    import gymnasium as gym

    from localization.workflows.tracking import fit_city_localizer

    if args.lanes not in LANES:
        raise UsageError("lanes", f"must be one of {', '.join(LANES)}, got {args.lanes!r}")
    if args.n_train < 1:
        raise UsageError("n-train", f"must be >= 1, got {args.n_train}")
    if args.n_drive < MIN_DRIVE:  # the noise's correlation time needs 4 blocks of 50 steps
        raise UsageError("n-drive", f"must be >= {MIN_DRIVE}, got {args.n_drive}")
    if args.districts < 1:
        raise UsageError("districts", f"must be >= 1, got {args.districts}")
    if args.overlap < 0:
        raise UsageError("overlap", f"must be >= 0, got {args.overlap}")
    check_env(args)
    params = localizer_params(args)
    env = gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, city_size=args.city_size,
                   camera=args.camera, image_size=(args.image_size, args.image_size),
                   motion_noise=args.motion_noise, max_episode_steps=None)
    try:
        with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            loc, seconds = fit_city_localizer(env, args.n_train, args.lanes, args.n_drive,
                                              seed=args.seed, localizer_params=params,
                                              progress=True, districts=None if
                                              args.districts == 1 else (args.districts,) * 2,
                                              overlap=args.overlap)
    finally:
        env.close()
    print("fitted on city {} ({}): {}".format(
        args.scene_seed, args.camera, ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items())))
    q = loc.quality_
    print(f"quality on a held-out drive of {q['steps']:.0f} steps: position RMSE "
          f"{q['rmse']:.3f} m vs dead reckoning {q['rmse_dead_reckoning']:.3f} m, "
          f"{q['accepted']:.0%} accepted, mean NEES {q['nees_mean']:.2f}")
    loc.save(out)


def run(args: Args) -> None:
    """Fit and save the localizer (options are checked before any long work)."""
    out = check_out(args.out, ".npz")
    if args.data:
        fit_recorded(args, out)
    else:
        fit_city(args, out)
    print(f"wrote {out}")
