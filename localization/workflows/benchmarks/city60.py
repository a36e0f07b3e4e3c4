"""Benchmark of a city nine times the default's area (issue 13, deliverable 4:
``appearance-nav bench --only city60``; its options are ``--city60-<option>``).

    appearance-nav bench --only city60                  # held-out 60 m cities 51, 52
    appearance-nav bench --only city60 --city60-quick   # smoke run (seconds)

On each city of ``cities`` (``city_size`` = 60 m: 9 x 9 blocks, 2000 m^2 of streets, 7.8
times the default city's) a street-wide localizer is fitted with
:func:`~localization.workflows.tracking.fit_city_localizer` (``lanes="streets"``, 64 x 64
perspective, ``features``: by default the packaged SmallCNN of random views of other cities,
PCA ``n_components``, chosen on tuning cities 11 and 12, :mod:`.street_features`) on
:func:`~localization.workflows.tracking.street_train_size` images: ``density`` images per
square metre of street, so the training set grows with the street area. By default it is a
:class:`~localization.districts.DistrictLocalizer` of ``districts`` x ``districts`` maps
sharing ``overlap`` metres (docs/method.md §12.1); ``districts=1`` fits one map of the city
(GSE's scalable path at this size). Then:

* single images: psi*'s position error on ``n_single`` held-out street-lane images (median,
  share over 1 m);
* closed loop: ``n_drives`` random street tours of ``drive_steps`` steps
  (:func:`~localization.workflows.tracking.track_streets`, EKF, "representation" model) on
  the belief mean (with ``recover``, the default, an :class:`agents.recovery.Recovery` backs
  off after contacts and looks around while the belief is lost, as the scripted agent does,
  and keeps its course at ``hold_speed`` while the belief is unconfirmed; chosen on tuning
  cities 53, 56 and 57, docs/benchmarks.md §10); the metres each tour drove;
  position RMSE pooled over the drives against dead reckoning's on the same controls, and
  the mean of the run-averaged NEES against its 95 % chi-square band
  (:func:`~localization.workflows.tracking.nees_band`). Target (issue 13): RMSE <= 0.20 m.
* agents: ``episodes`` episodes of the scripted agent (:class:`agents.scripted.ScriptedAgent`,
  car-like "drive" plans) from a street lane to a random street goal on the belief, and the
  same episodes on the true pose (the oracle: what the planner and the episode limit allow),
  truncated at :func:`envs.episode_steps` of the city (1500 steps); success rates.

Cities 51, 52 were never used to choose anything; ``districts``, ``overlap`` and ``density``
were set on tuning city 53 (docs/benchmarks.md §10); cities 56 and 57 are a second and a
third tuning city (stops 62, 63). One map of the city at 24 images a
square metre (48000) folds: psi*'s median error 10.1 m, belief RMSE 31.6 m. 3 x 3 districts
of the same images: median 0.22 m (but 22 % of images off by more than 1 m), and one of
three 1000-step tours lost (0.66 m RMSE). At the default city's density, 47 a square metre
(94000 images; the nine fits take about 5 minutes): tours of 0.047, 0.122 and 0.083 m. A fit
whose neighbour graph falls apart is reported (``fit_failures``) and the run goes on. With
``localizer_dir`` each city's fit is saved and a later run loads it (trying filter settings
on the same maps without the half hour a city's fit takes).
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # chooses MUJOCO_GL before mujoco is imported

# isort: split
import gymnasium as gym
import numpy as np
from tqdm import tqdm

from agents.evaluation import as_records, run_episodes, summarize
from agents.recovery import Recovery
from agents.scripted import ScriptedAgent
from agents.sources import make_pose_env
from envs.datasets import collect_dataset
from localization.loading import load_localizer
from localization.localizer import city_info
from localization.workflows.benchmarks.coverage import summarize_drives
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.benchmarks.street_features import features_label, localizer_features
from localization.workflows.tracking import (
    fit_city_localizer,
    street_train_size,
    track_metrics,
    track_streets,
)

__all__ = ["RMSE_TARGET", "City60BenchConfig", "markdown", "run_city60_bench"]

#: issue 13: closed-loop belief RMSE on a 60 m city (m)
RMSE_TARGET = 0.20


@dataclass
class City60BenchConfig:
    """Settings of the 60 m city benchmark."""

    cities: str = field(default="51,52", metadata={
        "help": "comma-separated scene seeds (51, 52: never used to choose anything)"})
    city_size: float = field(default=60.0, metadata={"help": "side of the cities (m)"})
    image_size: int = field(default=64, metadata={"help": "square image side (px)"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    density: float = field(default=47.0, metadata={
        "help": "street-lane training images per square metre of street (chosen on city 53)"})
    lane_heading: float = field(default=0.2, metadata={
        "help": "largest heading offset (rad) of the training images from their lane (the "
                "maps' heading tube; envs.lanes' default)"})
    features: str = field(default="small_cnn", metadata={
        "help": "small_cnn (the packaged SmallCNN of random views of other cities, whole "
                "image) or pixel_pca (PixelPCA on the localizer's upper image rows)"})
    n_components: int = field(default=64, metadata={"help": "PCA components of the features"})
    districts: int = field(default=3, metadata={
        "help": "a DistrictLocalizer of n x n districts (chosen on city 53); 1: one map of "
                "the whole city"})
    overlap: float = field(default=4.0, metadata={
        "help": "metres of training images shared by neighbouring districts"})
    filter: str = field(default="ekf", metadata={
        "help": "the belief of the tours and the agent: 'ekf' or 'particles'"})
    heading_check: float = field(default=0.05, metadata={
        "help": "the EKF undoes a representation update that turns its heading more than this "
                "(rad) away from the image's own psi* (BeliefFilter heading_check; chosen on "
                "city 53); 0: off"})
    familiar_novelty: float = field(default=3.0, metadata={
        "help": "the EKF restarts only from images whose relative novelty is at most this, "
                "and checks a start from a more novel first image against the first familiar "
                "one (BeliefFilter familiar_novelty; chosen on city 53; district maps only); "
                "0: off"})
    turn_response: bool = field(default=False, metadata={
        "help": "the EKF predicts the turn rate the robot really turns at for each command "
                "(localization.filtering.turn_response; BeliefFilter turn_response; off: on 240 tuning tours "
                "of cities 53, 56 and 57 it read 0.375 m against 0.323, stop 64)"})
    recover: bool = field(default=True, metadata={
        "help": "the tour pilot backs off after a contact and stops to look along the streets "
                "while the belief is lost, as the scripted agent does (agents.Recovery; "
                "chosen on cities 53 and 56)"})
    hold_speed: float = field(default=0.3, metadata={
        "help": "with --city60-recover, the tour pilot keeps its course at this speed (m/s) "
                "while the belief is 'relocalizing' (a start or restart not yet confirmed) "
                "instead of steering on it (Recovery hold_speed; chosen on cities 53, 56 and "
                "57); 0: steer on it"})
    n_drive: int = field(default=1500, metadata={"help": "steps of each noise-calibration drive"})
    n_drives: int = field(default=6, metadata={
        "help": "street tours per city (6: with 3, held-out city 51 showed one lost tour of "
                "three where six showed three of six, stop 61)"})
    drive_steps: int = field(default=1000, metadata={"help": "steps of each street tour"})
    episodes: int = field(default=10, metadata={"help": "scripted-agent episodes per city"})
    n_single: int = field(default=1000, metadata={
        "help": "held-out street-lane images for psi*'s single-image error"})
    max_episode_steps: int = field(default=0, metadata={
        "help": "truncation of agent episodes (0: envs.episode_steps(city_size))"})
    quick: bool = field(default=False, metadata={"help": "smoke run: one small city, tiny fits"})
    seed: int = field(default=0, metadata={"help": "seed of fits, drives and episodes"})
    out_dir: str = field(default="results", metadata={"help": "where bench_city60.json/.md go"})
    localizer_dir: str = field(default="", metadata={
        "help": "a folder for the fitted localizers (about 0.8 GB a city): each city's fit is "
                "saved there as localizer_<city>.npz and loaded from there when the file "
                "exists (same settings), so another run of the tours and the agent skips the "
                "fit; empty: fit every run, save nothing"})

    def resolved(self) -> City60BenchConfig:
        """The settings actually run (``quick``: one city, 32 px, small fits, short runs)."""
        if not self.quick:
            return self
        return dataclasses.replace(
            self, cities=self.cities.split(",")[0], image_size=32, density=1.0,
            n_components=8, n_drive=200, n_drives=1, drive_steps=40, episodes=1, n_single=20,
            max_episode_steps=40)

    def city_list(self) -> list[int]:
        """``cities`` as ints."""
        return [int(s) for s in self.cities.split(",")]


def make_env(args: City60BenchConfig, city: int) -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, city_size=args.city_size,
                    image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise)


def fit_city(args: City60BenchConfig, env: gym.Env) -> tuple[Any, dict[str, float], int]:
    """The street-wide localizer of the env's city, the seconds of its stages and its n."""
    n_train = street_train_size(env, args.density)
    with warnings.catch_warnings():  # GSE's eigen-gap warnings; the quality is measured here
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        warnings.filterwarnings("ignore", message=".*quality.*")
        loc, seconds = fit_city_localizer(
            env, n_train=n_train, lanes="streets", n_drive=args.n_drive, seed=args.seed,
            localizer_params=localizer_features(args.features, env.unwrapped.camera_name,
                                                args.n_components),
            measurements=("representation",), quality_steps=0,
            districts=None if args.districts == 1 else (args.districts, args.districts),
            overlap=args.overlap, lane_options={"heading": args.lane_heading})
    return loc, seconds, n_train


def localizer_path(args: City60BenchConfig, city: int) -> Path | None:
    """Where ``city``'s localizer is kept (None without ``localizer_dir``)."""
    return Path(args.localizer_dir) / f"localizer_{city}.npz" if args.localizer_dir else None


def fit_or_load(args: City60BenchConfig, env: gym.Env, city: int
                ) -> tuple[Any, dict[str, float], int]:
    """:func:`fit_city`, or the localizer saved at :func:`localizer_path` by an earlier run
    (checked against the env's city and image size); a new fit is saved there."""
    path = localizer_path(args, city)
    if path is not None and path.exists():
        t = time.perf_counter()
        loc = load_localizer(path)
        try:
            loc.check_city(city_info(env))
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
        if tuple(loc.image_size_) != (args.image_size, args.image_size):
            raise ValueError(f"{path} holds maps of {loc.image_size_} images, not "
                             f"{args.image_size} px: fitted with other settings")
        return loc, {"load": time.perf_counter() - t}, street_train_size(env, args.density)
    loc, sec, n_train = fit_city(args, env)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        loc.save(path)
    return loc, sec, n_train


def single_image_errors(args: City60BenchConfig, env: gym.Env, loc: Any, seed: int
                        ) -> list[float]:
    """psi*'s position error (m) on ``n_single`` held-out street-lane images (NaN: out of
    every map's domain)."""
    images, poses = collect_dataset(env, args.n_single, "lanes", seed=seed, lanes="streets",
                                    progress=False)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        pred = loc.predict(images)
    return np.hypot(*(pred[:, :2] - poses[:, :2]).T).tolist()


def tours(args: City60BenchConfig, env: gym.Env, loc: Any, base: int) -> list[dict[str, float]]:
    """The closed-loop street tours of one city (seeds ``base + k``)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        return [track_metrics(track_streets(env, loc, "representation", args.drive_steps,
                                            seed=base + k, recover=_recovery(args, env),
                                            **_belief(args)))
                for k in range(args.n_drives)]


def _recovery(args: City60BenchConfig, env: gym.Env) -> Recovery | bool:
    """The tours' :class:`~agents.recovery.Recovery` (False without ``recover``)."""
    if not args.recover:
        return False
    return Recovery(env.unwrapped.W_MAX, hold_speed=args.hold_speed or None)


def _belief(args: City60BenchConfig) -> dict[str, Any]:
    """BeliefWrapper options of ``args.filter`` (the particles spread over the city's free
    streets by default; the EKF with ``turn_response``, ``heading_check`` and, on district
    maps, ``familiar_novelty`` unless they are off)."""
    if args.filter != "ekf":
        return {"filter": "particles"}
    options: dict[str, float | bool] = {}
    if args.turn_response:
        options["turn_response"] = True
    if args.heading_check:
        options["heading_check"] = args.heading_check
    if _familiar(args):
        options["familiar_novelty"] = args.familiar_novelty
    return {"filter_options": options} if options else {}


def _familiar(args: City60BenchConfig) -> bool:
    """Whether the EKF's restarts wait for familiar images (district maps rate them)."""
    return args.filter == "ekf" and args.familiar_novelty > 0 and args.districts > 1


def agent_runs(args: City60BenchConfig, loc: Any, city: int, base: int
               ) -> dict[str, list[dict[str, Any]]]:
    """The scripted agent's episodes on the belief and on the true pose (same reset seeds)."""
    limit = args.max_episode_steps or envs.episode_steps(args.city_size)
    out = {}
    for source in ("belief", "oracle"):
        env = make_pose_env(source, loc if source == "belief" else None, scene_seed=city,
                            city_size=args.city_size, motion_noise=args.motion_noise,
                            image_size=(args.image_size, args.image_size),
                            max_episode_steps=limit,
                            **(_belief(args) if source == "belief" else {}))
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
            episodes = run_episodes(env, ScriptedAgent(env.unwrapped.city),
                                    range(base, base + args.episodes), progress=False)
        env.close()
        out[source] = as_records(episodes)
    return out


def _agents_summary(records: list[dict[str, Any]]) -> dict[str, float]:
    from agents.evaluation import Episode

    fields = {f.name for f in dataclasses.fields(Episode)}
    return summarize([Episode(**{k: v for k, v in r.items() if k in fields}) for r in records])


def summarize_city(rec: dict[str, Any]) -> dict[str, Any]:
    """The rows of one city (or of all: records concatenated)."""
    single = np.asarray(rec.get("single_image", []), dtype=np.float64)
    return {"single_image": {"images": len(single),
                             "median": float(np.nanmedian(single)) if len(single) else np.nan,
                             "over_1m": float(np.mean(~(single <= 1.0))) if len(single)
                             else np.nan},
            "closed_loop": summarize_drives(rec["drives"]),
            "agents": {s: _agents_summary(rec["agents"][s]) for s in ("belief", "oracle")}}


def _mark(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def markdown(result: dict[str, Any]) -> str:
    """The benchmark's tables (per city and pooled), targets marked PASS / MISS."""
    lines = [f"60 m cities ({result['setup']}):", "",
             ("| city | training images | psi* median (m) | psi* > 1 m | street tours | "
              "driven (m per tour) | belief RMSE (m; <= 0.20) | "
              "dead reckoning RMSE (m) | ratio | largest error (m) | mean NEES [95 % band] | "
              "accepted | agent success on belief | on true pose |"),
             "|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---|---:|---:|---:|"]
    for name, s in result["summary"].items():
        c, a, one = s["closed_loop"], s["agents"], s["single_image"]
        lo, hi = c["nees_band"]
        n_train = s.get("n_train", "")
        lines.append(
            f"| {name} | {n_train} | {one['median']:.2f} | {100 * one['over_1m']:.0f} % | "
            f"{c['drives']} | {c['distance']:.1f} | {c['rmse']:.3f} "
            f"{_mark(c['rmse'] <= RMSE_TARGET)} | {c['rmse_dead_reckoning']:.2f} | "
            f"{c['ratio']:.3f} | {c['max_error']:.2f} | {c['nees_mean']:.2f} [{lo:.2f}, "
            f"{hi:.2f}] {_mark(lo <= c['nees_mean'] <= hi)} | {100 * c['accepted']:.0f} % | "
            f"{100 * a['belief']['success_rate']:.0f} % of {a['belief']['episodes']} | "
            f"{100 * a['oracle']['success_rate']:.0f} % |")
    lines += [f"\nFit failed: {f}" for f in result.get("fit_failures", [])]
    lines += ["", "Seconds per city: " + "; ".join(
        f"{s['city']}: " + ", ".join(f"{k} {v:.0f}" for k, v in s.items() if k != "city")
        for s in result["stage_seconds"])]
    return "\n".join(lines) + "\n"


def _result(args: City60BenchConfig, records: dict[int, dict[str, Any]],
            seconds: list[dict[str, Any]], t0: float) -> dict[str, Any]:
    summary: dict[str, Any] = {str(c): {**summarize_city(r), "n_train": r["n_train"]}
                               for c, r in records.items()}
    if len(records) > 1:
        pooled = {"drives": [d for r in records.values() for d in r["drives"]],
                  "single_image": [e for r in records.values() for e in r["single_image"]],
                  "agents": {s: [e for r in records.values() for e in r["agents"][s]]
                             for s in ("belief", "oracle")}}
        summary["all"] = summarize_city(pooled)
    limit = args.max_episode_steps or envs.episode_steps(args.city_size)
    return {"args": dataclasses.asdict(args), **provenance(),
            "seconds": time.perf_counter() - t0, "stage_seconds": seconds,
            "summary": summary, "records": {str(c): r for c, r in records.items()},
            "setup": f"cities {','.join(map(str, records)) or 'none'}, {args.city_size:g} m, "
                     f"{args.image_size}x{args.image_size} perspective, motion noise "
                     f"{args.motion_noise}, {features_label(args.features, args.n_components)} "
                     f"on {args.density:g} "
                     f"street-lane images per m^2 of street (headings within "
                     f"{args.lane_heading:g} rad of the lane), "
                     f"{_maps(args)}, {_filter_label(args)}; {args.n_drives} street tour(s) of "
                     f"{args.drive_steps} steps and {args.episodes} agent episode(s) "
                     f"(<= {limit} steps) per city"}


def _filter_label(args: City60BenchConfig) -> str:
    parts = [f"{args.filter} belief"]
    if args.filter == "ekf" and args.turn_response:
        parts.append("turns predicted at the robot's measured rate")
    if args.filter == "ekf" and args.heading_check:
        parts.append(f"heading checked against psi* ({args.heading_check:g} rad)")
    if _familiar(args):
        parts.append(f"restarts from familiar images (novelty <= {args.familiar_novelty:g})")
    if args.recover:
        parts.append("the tour pilot backs off after contacts and looks around while lost")
        if args.hold_speed:
            parts.append(f"keeps its course at {args.hold_speed:g} m/s while relocalizing")
    return ", ".join(parts)


def _maps(args: City60BenchConfig) -> str:
    if args.districts == 1:
        return "one map of the city"
    return (f"{args.districts} x {args.districts} districts sharing {args.overlap:g} m "
            "(DistrictLocalizer)")


def run_city60_bench(args: City60BenchConfig) -> dict[str, Any]:
    """Run the benchmark; write ``bench_city60.json`` / ``.md`` (after every city); return the
    result."""
    args = args.resolved()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    records: dict[int, dict[str, Any]] = {}
    seconds: list[dict[str, Any]] = []
    failures: list[str] = []
    result: dict[str, Any] = {}
    for i, city in enumerate(tqdm(args.city_list(), desc="bench city60", leave=False)):
        base = args.seed + 10_000 * (i + 1)
        env = make_env(args, city)
        try:
            loc, sec, n_train = fit_or_load(args, env, city)
        except ValueError as err:  # e.g. GSE's neighbour graph leaves samples on their own
            failures.append(f"city {city}: {err}")
            env.close()
            result = _write(out, _result(args, records, seconds, t0), failures)
            continue
        t1 = time.perf_counter()
        single = single_image_errors(args, env, loc, base + 300)
        sec["single"] = time.perf_counter() - t1
        t1 = time.perf_counter()
        drives = tours(args, env, loc, base + 100)
        sec["tours"] = time.perf_counter() - t1
        env.close()
        t1 = time.perf_counter()
        agents = agent_runs(args, loc, city, base + 200)
        sec["agents"] = time.perf_counter() - t1
        records[city] = {"n_train": n_train, "single_image": single, "drives": drives,
                         "agents": agents}
        seconds.append({"city": city, **sec})
        result = _write(out, _result(args, records, seconds, t0), failures)
    print(markdown(result))
    return result


def _write(out: Path, result: dict[str, Any], failures: list[str]) -> dict[str, Any]:
    """Add the failed fits to ``result`` and write the JSON and the table (after every city:
    a long run keeps its part)."""
    result["fit_failures"] = list(failures)
    (out / "bench_city60.json").write_text(json.dumps(result, indent=2))
    (out / "bench_city60.md").write_text(markdown(result))
    return result
