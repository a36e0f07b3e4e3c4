"""Closed-loop tracking: fit a localizer for a city, drive its route on the belief, score it.

Shared by the tracking runs (:mod:`.track_runs`), the demo (:mod:`.demo`), the filter
benchmark (:mod:`.benchmarks.filter`) and the tests.

- :func:`street_train_size`: a training-set size that grows with the city's street area.
- :func:`fit_city_localizer`: the whole fit on one city: images around the driving lanes
  (``envs.collect_dataset(mode="lanes")``), :meth:`AppearanceLocalizer.fit`, a drive on the
  true pose for the process and measurement noise (:meth:`AppearanceLocalizer.fit_noise`)
  and a first consistency calibration (:meth:`AppearanceLocalizer.calibrate`), then a drive
  on that belief (closed loop, "representation" model) on which the calibration is refined:
  in closed loop the robot follows the belief's errors, which the true-pose drive does not
  show. The drives go where the training lanes go: around the route (``lanes="route"``) or
  along random tours of all the streets, both ways (``lanes="streets"``); or, with
  ``lanes="free"``, the images cover the whole street surface at every heading
  (``collect_dataset(mode="coverage")``, :mod:`envs.coverage`) and the drives leave the lanes
  (:func:`envs.datasets.drive_off_lane`: weaving, U-turns, turning on the spot). The localizer
  records its city (``city_``, :func:`~localization.localizer.city_info`) and, from one more
  held-out drive, its quality report ``quality_`` (:mod:`.quality`), with a
  :class:`~localization.workflows.quality.LocalizerQualityWarning` when it is poor.
- :func:`track_route` / :func:`track_streets` / :func:`track_off_lane`: drive ``steps`` steps
  along the route / a random street tour / an off-lane drive (:mod:`envs.off_lane`) with a
  controller on the belief mean
  (:class:`~localization.wrappers.BeliefWrapper`), and dead-reckon the same commanded
  controls from the true start pose (F alone). They refuse a localizer of another city
  unless ``allow_other_city=True``.
- :func:`track_metrics`: position RMSE of the belief and of dead reckoning, their ratio,
  heading RMSE, mean NEES and NIS, measurement acceptance.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from agents.recovery import Recovery
from envs.datasets import (
    PurePursuit,
    collect_dataset,
    drive_off_lane,
    drive_route,
    drive_streets,
    off_lane_pilot,
)
from envs.lanes import street_tour
from envs.off_lane import OffLanePilot
from localization._validation import check_real
from localization.districts import DistrictLocalizer
from localization.experiences import ExperienceLocalizer
from localization.geometry import Array, wrap_angle
from localization.localizer import MEASUREMENTS, AppearanceLocalizer, city_info
from localization.workflows.quality import quality_report, warn_quality
from localization.wrappers import BeliefWrapper

#: training sets of :func:`fit_city_localizer`: the route's lanes, every street's, or the
#: whole street surface at every heading
TRAININGS = ("route", "streets", "free")


@dataclass
class TrackResult:
    """One closed-loop run of ``steps`` steps (arrays have ``steps + 1`` rows: frame 0 is the
    reset). ``dead_reckoning`` is F alone from the true start pose with the same controls."""

    measurement: str
    true: Array
    mean: Array
    cov: Array
    dead_reckoning: Array
    controls: Array
    nis: Array
    nis_dof: int
    nees: Array
    status: list[str]
    seconds_per_step: float
    images: NDArray[np.uint8] | None = field(default=None, repr=False)


#: filter options of the drives that judge a localizer (its calibration on the belief and its
#: quality report): the belief from its images, without the map's contact projection
#: (``BeliefFilter(project_contacts=...)``), which would hide a map that needs more images
#: (an under-trained map's belief, 200 images on city 0, read 0.2x dead reckoning with it,
#: worse than dead reckoning without, tests/localization/test_localizer_map.py)
IMAGES_ONLY = {"project_contacts": False}


def fit_city_localizer(env: gym.Env, n_train: int = 6000, lanes: str = "route",
                       n_drive: int = 1500, seed: int = 0,
                       localizer_params: dict[str, Any] | None = None,
                       lane_options: dict[str, Any] | None = None,
                       calibrate_on_belief: bool = True,
                       measurements: tuple[str, ...] = MEASUREMENTS, progress: bool = False,
                       quality_steps: int | None = None,
                       districts: tuple[int, int] | None = None, overlap: float = 4.0,
                       noise_env: gym.Env | None = None,
                       experience_envs: Sequence[gym.Env] = (),
                       ) -> tuple[AppearanceLocalizer | DistrictLocalizer, dict[str, float]]:
    """Fit an :class:`AppearanceLocalizer` and its noise model on the env's city.

    Parameters
    ----------
    env : an AppearanceNav env (its motion noise is the one the noise model learns).
    n_train : int
        Training images around the lanes (or over the street surface).
    lanes : {"route", "streets", "free"}
        Lanes of the training images (see :mod:`envs.lanes`), or "free": the whole street
        surface at every heading (:mod:`envs.coverage`).
    n_drive : int
        Steps of each noise drive (around the route for ``lanes="route"``, along random
        street tours for ``lanes="streets"``, off-lane drives for ``lanes="free"``).
    seed : int
        Seeds the training poses and the drives (drive seeds ``seed + 1``, ``seed + 2``).
    localizer_params : dict, optional
        Keyword arguments of :class:`AppearanceLocalizer` (default ``noise_folds=0``: R comes
        from the drives).
    lane_options : dict, optional
        Extra options of the "lanes" dataset (``lateral``, ``heading``, ...), or for
        ``lanes="free"`` of the "coverage" one (``region``, ``corner_weight``, ...).
    calibrate_on_belief : bool
        After calibrating the consistency on the true-pose drive, refine it on a drive on
        that belief (closed loop, "representation" model).
    measurements : tuple of str
        Models whose consistency is calibrated.
    progress : bool
    quality_steps : int, optional
        Steps of the held-out drive of the quality report (seed ``seed + 3``; default
        ``n_drive``; 0 skips it: its scores are then NaN).
    districts : (int, int), optional
        Fit a :class:`~localization.districts.DistrictLocalizer` with this grid of
        districts (``overlap`` metres of hand-over zone), each an AppearanceLocalizer of
        ``localizer_params``: for large cities, where one map folds.
    noise_env : gym.Env, optional
        Env of the noise, calibration and quality drives (default ``env``): the same city
        in other conditions, e.g. a map fitted on daylight images whose measurement noise
        is learnt under randomised conditions (``conditions="random"``).
    experience_envs : sequence of gym.Env, optional
        The same city in other looks (e.g. ``conditions=`` a dusk or a night draw): the map
        becomes an :class:`~localization.experiences.ExperienceLocalizer`, one map per look
        (``env``'s first, each of the same training poses; labels ``"<k>:<look name>"``),
        and each image is measured by the look it resembles most.

    Returns
    -------
    localizer : AppearanceLocalizer
        Fitted with the env's city (``city_``) and its quality report ``quality_``
        (:func:`~localization.workflows.quality.quality_report`; the held-out drive uses the
        "representation" model, or the first of ``measurements`` without it).
    seconds : dict
        Wall time of each stage ("collect", "fit", "noise", "quality").

    Warns
    -----
    LocalizerQualityWarning
        If the belief is worse than dead reckoning on the held-out drive or a consistency
        factor reached its bound (:func:`~localization.workflows.quality.warn_quality`).
    """
    steps = n_drive if quality_steps is None else int(quality_steps)
    if steps < 0:
        raise ValueError(f"quality_steps must be >= 0 or None, got {quality_steps}")
    _check_training(lanes)
    drive_env = env if noise_env is None else _same_city(env, noise_env)
    seconds = {}
    t0 = time.perf_counter()
    params = {"noise_folds": 0, **(localizer_params or {})}
    loc: AppearanceLocalizer | DistrictLocalizer = AppearanceLocalizer(**params)
    looks = [env, *(_same_city(env, e, "experience_envs") for e in experience_envs)]
    if districts is not None and len(looks) > 1:
        raise ValueError("districts and experience_envs cannot be combined: fit one or the other")
    parts = [_training_images(e, loc, n_train, lanes, seed, lane_options, progress)
             for e in looks]
    images = np.concatenate([p[0] for p in parts])
    poses = np.concatenate([p[1] for p in parts])
    seconds["collect"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    where = {"camera": getattr(env.unwrapped, "camera_name", None), "city": city_info(env)}
    if districts is not None:
        loc = DistrictLocalizer(grid=districts, overlap=overlap, localizer_params=params)
    if len(looks) > 1:
        names = [f"{k}:{e.unwrapped.conditions.name}" for k, e in enumerate(looks)]
        labels = np.repeat(names, [len(p[1]) for p in parts])
        loc = ExperienceLocalizer(localizer_params=params).fit(images, poses,
                                                               experiences=labels, **where)
    else:
        loc.fit(images, poses, **where)
    seconds["fit"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit_city_noise(drive_env, loc, lanes, n_drive, seed, calibrate_on_belief, measurements,
                   progress)
    seconds["noise"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    metrics = None
    if steps > 0:
        model = "representation" if "representation" in measurements else measurements[0]
        track = TRACKS[lanes]
        metrics = track_metrics(track(drive_env, loc, model, steps, seed=seed + 3,
                                      filter_options=IMAGES_ONLY))
    loc.quality_ = quality_report(metrics, loc.consistency_)
    seconds["quality"] = time.perf_counter() - t0
    warn_quality(loc.quality_)
    return loc, seconds


def _training_images(env: gym.Env, loc: AppearanceLocalizer, n_train: int, lanes: str,
                     seed: int, lane_options: dict[str, Any] | None, progress: bool
                     ) -> tuple[NDArray[np.uint8], Array]:
    """The map's images of one env: around its lanes, or over the whole street surface
    (``lanes="free"``, less views ``loc`` cannot tell apart)."""
    if lanes == "free":
        images, poses = collect_dataset(env, n_train, "coverage", seed=seed, progress=progress,
                                        **(lane_options or {}))
        return distinct_views(loc, images, poses)
    return collect_dataset(env, n_train, "lanes", seed=seed, progress=progress, lanes=lanes,
                           **(lane_options or {}))


def _same_city(env: gym.Env, other: gym.Env, name: str = "noise_env") -> gym.Env:
    """``other`` (the argument ``name``) after checking it shows ``env``'s city (ValueError
    otherwise)."""
    theirs, ours = city_info(other), city_info(env)
    if theirs != ours:
        raise ValueError(f"{name} must show the same city as env, got scene_seed "
                         f"{theirs['scene_seed']} (city_size {theirs['city_size']}) against "
                         f"{ours['scene_seed']} ({ours['city_size']})")
    return other


def street_train_size(env: gym.Env, density: float) -> int:
    """Training images for ``env``'s city at ``density`` images per square metre of street
    (``city.street_area()``): ``ceil(density x area)``. A fixed n thins out as the city grows
    (a 60 m city has 7.8 times the default city's 256 m^2 of streets); a density does not.
    The 60 m benchmark's density was chosen on tuning city 53 (docs/benchmarks.md §10).

    Raises
    ------
    ValueError
        If ``density`` is not a positive finite number.
    """
    density = check_real(density, "density", low=0.0, low_open=True)
    return max(1, math.ceil(density * env.unwrapped.city.street_area() - 1e-9))


def distinct_views(localizer: AppearanceLocalizer, images: NDArray[np.uint8], poses: Array
                   ) -> tuple[NDArray[np.uint8], Array]:
    """Drop every image whose rows seen by ``localizer`` (its ``rows``) are identical to
    another's: (images (n', H, W, 3), poses (n', 3)).

    At every heading some coverage poses face a building wall from a few decimetres: the
    view is one flat colour, the same at many poses, and identical samples stop GSE's graph
    (2 of 20000 at 64 x 64 on city 12). No pose can be read from such a view, so all its
    copies go.
    """
    flat = localizer._crop(images).reshape(len(images), -1)
    _, inverse, counts = np.unique(flat, axis=0, return_inverse=True, return_counts=True)
    keep = counts[inverse.ravel()] == 1
    return images[keep], poses[keep]


def fit_city_noise(env: gym.Env, localizer: AppearanceLocalizer, lanes: str = "route",
                   n_drive: int = 1500, seed: int = 0, calibrate_on_belief: bool = True,
                   measurements: tuple[str, ...] = MEASUREMENTS, progress: bool = False,
                   ) -> AppearanceLocalizer:
    """The noise stage of :func:`fit_city_localizer` for a fitted localizer (same arguments):
    noise from a drive on the true pose (seed ``seed + 1``), consistency calibrated on it
    and then on a drive on the belief (seed ``seed + 2``; the belief of the images alone,
    :data:`IMAGES_ONLY`, as the quality drive's)."""
    _check_training(lanes)
    motion_model = env.unwrapped.motion_model
    drive = {"route": drive_route, "streets": drive_streets, "free": drive_off_lane}[lanes]
    images, poses, controls = drive(env, n_drive, seed=seed + 1, progress=progress)
    try:
        localizer.fit_noise(motion_model, images, poses, controls)
    except ValueError as err:  # too few (finite) residuals for a covariance or its time
        raise ValueError(f"n_drive={n_drive} is too short a drive for the noise model: {err}; "
                         "raise n_drive or lower the feature dimension "
                         "(features_params n_components)") from err
    localizer.calibrate(motion_model, images, poses, controls, measurements)
    if calibrate_on_belief:
        run = TRACKS[lanes](env, localizer, "representation", n_drive, seed=seed + 2,
                            keep_images=True, filter_options=IMAGES_ONLY)
        localizer.calibrate(motion_model, run.images, run.true, run.controls, measurements)
    return localizer


def track_route(env: gym.Env, localizer: AppearanceLocalizer, measurement: str,
                steps: int, start: int = 0, seed: int = 0, keep_images: bool = False,
                allow_other_city: bool = False,
                recorder: Callable[[gym.Env], gym.Env] | None = None,
                recover: bool | Recovery = False, **wrapper_options: Any) -> TrackResult:
    """Drive ``steps`` steps along the city's route on the belief mean.

    The robot starts on the route's path point ``start`` (``PurePursuit.path``), heading
    along it; :class:`PurePursuit` steers on the belief mean (never on the true pose).
    ``wrapper_options`` go to :class:`BeliefWrapper`; ``recorder`` wraps it for the drive
    (e.g. a :class:`~localization.workflows.rerun_log.RerunRecorder`). A localizer fitted on
    another city raises :class:`~localization.localizer.OtherCityError` unless
    ``allow_other_city``. With ``recover`` a :class:`~agents.recovery.Recovery` acts before
    the pilot: it backs off after a contact and, while ``info["belief_status"]`` is "lost",
    stops and looks along the street axes instead of steering on the belief; pass a
    :class:`~agents.recovery.Recovery` for other settings (e.g. ``hold_speed``).
    """
    base = env.unwrapped
    pilot = PurePursuit(base.city.route(), w_max=base.W_MAX)
    return _track(env, localizer, measurement, pilot, pilot.start_pose(start), steps, seed,
                  keep_images, allow_other_city, wrapper_options, recorder, recover)


def track_streets(env: gym.Env, localizer: AppearanceLocalizer, measurement: str,
                  steps: int, seed: int = 0, keep_images: bool = False,
                  speed: float = 0.6, allow_other_city: bool = False,
                  recover: bool | Recovery = False, **wrapper_options: Any) -> TrackResult:
    """Drive ``steps`` steps along a random tour of the streets (``envs.lanes.street_tour``
    drawn from ``seed``) on the belief mean, from the tour's first intersection (other
    arguments as :func:`track_route`)."""
    base = env.unwrapped
    tour = street_tour(base.city, 1.5 * steps * base.dt * speed + 10.0,
                       np.random.default_rng(seed))
    pilot = PurePursuit(tour, speed=speed, w_max=base.W_MAX, closed=False)
    return _track(env, localizer, measurement, pilot, pilot.start_pose(0), steps, seed,
                  keep_images, allow_other_city, wrapper_options, recover=recover)


def track_off_lane(env: gym.Env, localizer: AppearanceLocalizer, measurement: str,
                   steps: int, seed: int = 0, keep_images: bool = False,
                   speed: float = 0.6, allow_other_city: bool = False,
                   recover: bool | Recovery = False, **wrapper_options: Any) -> TrackResult:
    """Drive ``steps`` steps off the lanes (:func:`envs.off_lane.off_lane_waypoints` drawn from
    ``seed``: weaving across the streets, U-turns, turning on the spot at corners) with
    :class:`envs.off_lane.OffLanePilot` on the belief mean, from the first waypoint at a
    random heading (other arguments as :func:`track_route`)."""
    pilot, start = off_lane_pilot(env.unwrapped, steps, seed, speed)
    return _track(env, localizer, measurement, pilot, start, steps, seed,
                  keep_images, allow_other_city, wrapper_options, recover=recover)


#: the closed-loop drive of each training set
TRACKS: dict[str, Callable[..., TrackResult]] = {
    "route": track_route, "streets": track_streets, "free": track_off_lane}


def _check_training(lanes: object) -> None:
    if lanes not in TRAININGS:
        raise ValueError(f"unknown lanes {lanes!r}; choose one of {TRAININGS}")


def _track(env: gym.Env, localizer: AppearanceLocalizer, measurement: str,
           pilot: PurePursuit | OffLanePilot,
           start: Array, steps: int, seed: int, keep_images: bool, allow_other_city: bool,
           wrapper_options: dict[str, Any],
           recorder: Callable[[gym.Env], gym.Env] | None = None,
           recover: bool | Recovery = False) -> TrackResult:
    if measurement not in MEASUREMENTS:
        raise ValueError(f"unknown measurement {measurement!r}; choose one of {MEASUREMENTS}")
    base = env.unwrapped
    wrapped = BeliefWrapper(env, localizer, measurement, keep_image=keep_images,
                            allow_other_city=allow_other_city, **wrapper_options)
    driven = wrapped if recorder is None else recorder(wrapped)
    obs, info = driven.reset(seed=seed, options={"pose": start})
    rows = {"true": [info["pose"]], "mean": [wrapped.mean], "cov": [wrapped.cov],
            "nis": [info["nis"]], "nees": [info["nees"]]}
    status, controls, images = [info["measurement_status"]], [], [obs.get("image")]
    dr = [info["pose"].copy()]
    space = env.action_space
    recovery = _recovery(recover, base.W_MAX)
    t0 = time.perf_counter()
    for _ in range(steps):
        u = _steer(pilot, recovery, obs["pose_mean"].astype(np.float64), info)
        u = np.clip(u, space.low, space.high)
        obs, _, _, _, info = driven.step(u)
        controls.append(u)
        dr.append(base.motion_model.predict(dr[-1], localizer.control_gain_ * u))
        for k, v in (("true", info["pose"]), ("mean", wrapped.mean), ("cov", wrapped.cov),
                     ("nis", info["nis"]), ("nees", info["nees"])):
            rows[k].append(v)
        status.append(info["measurement_status"])
        images.append(obs.get("image"))
    seconds = (time.perf_counter() - t0) / max(steps, 1)
    return TrackResult(measurement, *(np.array(rows[k]) for k in ("true", "mean", "cov")),
                       np.array(dr), np.array(controls, dtype=np.float64).reshape(-1, 2),
                       np.array(rows["nis"], dtype=np.float64), info["nis_dof"],
                       np.array(rows["nees"], dtype=np.float64), status, seconds,
                       np.array(images) if keep_images else None)


def _recovery(recover: bool | Recovery, w_max: float) -> Recovery | None:
    """The drive's Recovery: a default one for True, none for False, ``recover`` itself
    (reset) when it is one."""
    if isinstance(recover, Recovery):
        recover.reset()
        return recover
    if not isinstance(recover, (bool, np.bool_)):
        raise TypeError(f"recover must be a bool or an agents.Recovery, got "
                        f"{type(recover).__name__}")
    return Recovery(w_max) if recover else None


def _steer(pilot: PurePursuit | OffLanePilot, recovery: Recovery | None, mean: Array,
           info: dict[str, Any]) -> Array:
    """The pilot's command on the belief ``mean``, unless ``recovery`` acts on ``info``."""
    u = None if recovery is None else recovery.act(float(mean[2]), info)
    return pilot(mean) if u is None else u.astype(np.float64)


def nees_band(n_runs: int, prob: float = 0.95, dof: int = 3) -> tuple[float, float]:
    """Two-sided band of the mean of ``n_runs`` run-averaged NEES values.

    Each run's time-averaged NEES counts as one chi2(dof) draw: the steps of one run are
    strongly correlated (the error changes over tens of steps), so they are not independent
    samples. The band is ``chi2.ppf([(1 - prob) / 2, (1 + prob) / 2], n_runs dof) / n_runs``.
    """
    lo, hi = chi2.ppf([(1.0 - prob) / 2.0, (1.0 + prob) / 2.0], n_runs * dof) / n_runs
    return float(lo), float(hi)


def _nan_mean(x: Array) -> float:
    """Mean of the entries that are not NaN; NaN (no warning) when there are none (a run whose every
    image was out of the maps' domain has no NIS)."""
    x = np.asarray(x, dtype=np.float64)
    ok = ~np.isnan(x)
    return float(x[ok].mean()) if ok.any() else float("nan")


def track_metrics(run: TrackResult) -> dict[str, float]:
    """Scores of one run (positions in metres, headings in radians; ``distance``: the path the
    robot drove, a stalled robot's is short)."""
    err = np.hypot(*(run.mean[:, :2] - run.true[:, :2]).T)
    dr = np.hypot(*(run.dead_reckoning[:, :2] - run.true[:, :2]).T)
    yaw = wrap_angle(run.mean[:, 2] - run.true[:, 2])
    rmse, rmse_dr = float(np.sqrt(np.mean(err ** 2))), float(np.sqrt(np.mean(dr ** 2)))
    status = np.array(run.status[1:])
    return {"steps": len(run.true) - 1, "rmse": rmse, "rmse_dead_reckoning": rmse_dr,
            "ratio": rmse / rmse_dr if rmse_dr > 0 else float("nan"),
            "final_error": float(err[-1]), "final_error_dead_reckoning": float(dr[-1]),
            "max_error": float(err.max()), "yaw_rmse": float(np.sqrt(np.mean(yaw ** 2))),
            "nees_mean": float(np.mean(run.nees)), "nis_mean": _nan_mean(run.nis),
            "nis_dof": run.nis_dof, "accepted": float(np.mean(status == "accepted")),
            "distance": float(np.hypot(*np.diff(run.true[:, :2], axis=0).T).sum()),
            "ms_per_step": 1e3 * run.seconds_per_step}
