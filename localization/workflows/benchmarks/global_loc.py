"""Benchmark of the beliefs that must notice they are lost (issue 12): kidnapping, global
localization, the look-alike city, nominal tracking and cost, every filter side by side
(``appearance-nav bench --only global``; its options are ``--global-<option>``).

    appearance-nav bench --only global                    # the full run (about 20 minutes)
    appearance-nav bench --only global --global-quick     # smoke run (under a minute)

Cities: ``cities`` (default 21, 22, 23) and the look-alike city ``lookalike_city`` (24,
``city_layout="lookalike"``) were never used to choose a default. On each, a street-wide
PixelPCA localizer is fitted with :func:`~localization.workflows.tracking.fit_city_localizer`
(the settings below); every filter of ``filters`` replays the same recorded drives
(:mod:`localization.workflows.kidnap_eval`: the robot drives the streets on its true pose).

Rows (recovered = position error < 0.5 m for 10 steps in a row):

* kidnapping: ``n_kidnaps`` drives over the cities (kidnapped >= 5 m after
  ``steps_before`` steps, ``steps_after`` more); recovery rate within 30 steps, median /
  95th percentile of the steps to recover (inf = not within the drive); while lost
  (error > 1 m after the kidnap), the share of steps where the status is one of
  :data:`LOST_STATUSES` or the 3-sigma position ellipse (d^2 <= 9) contains the truth.
  Targets: >= 95 % within 30 steps, median <= 10, admitted >= 90 %.
* global: ``n_global`` drives started with no pose (filters with a global start only:
  ``ParticleBelief.reset(mode="global")``); share localized within 30 steps. Target >= 95 %.
* look-alike: ``n_lookalike`` kidnap drives in the look-alike city; the share of runs whose
  belief sits on a wrong twin (within 1 m of a twin of the true pose, more than 1 m from
  it) for more than 20 steps in a row. Target <= 5 %.
* nominal: ``n_nominal`` drives of ``nominal_steps`` steps per city, no kidnap; position
  RMSE (target for each filter: <= 1.2 x the EKF's) and mean NEES (3 dof; target: in the
  95 % chi-square band of the mean over the drives).
* cost: ms per filter step on one core (BLAS threads limited to 1), over the nominal drives;
  target <= 20 ms with 2000 particles.
* agents: ``agent_episodes`` episodes per city of the scripted agent on each belief, kidnapped
  once per episode (:mod:`~localization.workflows.benchmarks.global_agents`); success rate.
  Target >= 90 % on the particle belief.

``n_train`` = 12000 street images per city was chosen on the tuning cities 11-13 (held-out
drive RMSE 0.10-0.19 m, 5-8 % of dead reckoning's); with 4000 the kNN graph of city 11 split
and the other cities' localizers were worse than dead reckoning.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np
from scipy.stats import chi2
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from agents.evaluation import summarize
from localization.geometry import wrap_angle
from localization.workflows import kidnap_eval as ke
from localization.workflows.benchmarks import global_agents as ga
from localization.workflows.benchmarks.global_report import markdown
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.tracking import fit_city_localizer

__all__ = ["LOST_STATUSES", "TARGETS", "GlobalBenchConfig", "run_global_bench"]

#: statuses that admit the belief is lost (or re-localizing / torn between hypotheses)
LOST_STATUSES = ("lost", "relocalizing", "ambiguous", "doubtful")
LOST_ERROR = 1.0  # m
TWIN_RADIUS = 1.0  # m
WRONG_TWIN_STEPS = 20
WITHIN = 30
TARGETS = {"recovered_within_30": 0.95, "median_steps": 10.0, "admitted_while_lost": 0.90,
           "global_within_30": 0.95, "wrong_twin_runs": 0.05, "rmse_ratio": 1.2,
           "ms_per_step": 20.0, "agent_success": 0.90}


@dataclass
class GlobalBenchConfig:
    """Settings of the global-localization benchmark."""

    cities: str = field(default="21,22,23", metadata={
        "help": "comma-separated scene seeds (never used to choose a default)"})
    lookalike_city: int = field(default=24, metadata={"help": "scene seed of the look-alike city"})
    filters: str = field(default="ekf,ekf_detect,particles", metadata={
        "help": "comma-separated filters of kidnap_eval.run_filter, side by side"})
    image_size: int = field(default=32, metadata={"help": "square image side (px)"})
    motion_noise: float = field(default=0.05, metadata={"help": "env actuation noise"})
    n_train: int = field(default=12000, metadata={"help": "street-lane training images per city"})
    n_drive: int = field(default=600, metadata={"help": "steps of each noise-calibration drive"})
    n_components: int = field(default=16, metadata={"help": "PixelPCA components"})
    n_kidnaps: int = field(default=120, metadata={"help": "kidnap drives over all cities"})
    steps_before: int = field(default=60, metadata={"help": "steps before each kidnap"})
    steps_after: int = field(default=60, metadata={"help": "steps after each kidnap"})
    n_global: int = field(default=30, metadata={"help": "global starts over all cities"})
    global_steps: int = field(default=60, metadata={"help": "steps of each global-start drive"})
    n_lookalike: int = field(default=30, metadata={"help": "kidnap drives in the look-alike city"})
    n_nominal: int = field(default=2, metadata={"help": "nominal drives per city"})
    nominal_steps: int = field(default=300, metadata={"help": "steps of each nominal drive"})
    agent_episodes: int = field(default=20, metadata={
        "help": "scripted-agent episodes per city, kidnapped once each"})
    agent_kidnap_at: int = field(default=40, metadata={"help": "step of each episode's kidnap"})
    agent_max_steps: int = field(default=600, metadata={"help": "truncation of agent episodes"})
    quick: bool = field(default=False, metadata={"help": "smoke run: one city, tiny fits"})
    seed: int = field(default=0, metadata={"help": "seed of fits and drives"})
    out_dir: str = field(default="results", metadata={"help": "where bench_global.json/.md go"})

    def resolved(self) -> GlobalBenchConfig:
        """The settings actually run (``quick``: one city, small fits, a few short drives)."""
        if not self.quick:
            return self
        return dataclasses.replace(
            self, cities=self.cities.split(",")[0], n_train=500, n_drive=200, n_components=8,
            n_kidnaps=2, steps_before=20, steps_after=40, n_global=1, global_steps=40,
            n_lookalike=1, n_nominal=1, nominal_steps=60, agent_episodes=1, agent_kidnap_at=10,
            agent_max_steps=40)

    def city_list(self) -> list[int]:
        """``cities`` as ints."""
        return [int(s) for s in self.cities.split(",")]

    def filter_list(self) -> list[str]:
        """``filters`` as names, each checked against :data:`kidnap_eval.FILTERS`."""
        names = [s.strip() for s in self.filters.split(",")]
        bad = [n for n in names if n not in ke.FILTERS]
        if bad or not names:
            raise ValueError(f"filters: unknown {bad}; choose from {list(ke.FILTERS)}")
        return names


# ---------------------------------------------------------------- per-drive scores
def admitted(means: np.ndarray, covs: np.ndarray, statuses: list[str], poses: np.ndarray,
             start: int) -> tuple[int, int]:
    """(steps lost, steps of them admitted) from frame ``start``: lost = error > 1 m;
    admitted = status in :data:`LOST_STATUSES` or the truth inside the 3-sigma ellipse."""
    e = poses[start:, :2] - means[start:, :2]
    lost = np.hypot(*e.T) > LOST_ERROR
    P = covs[start:, :2, :2]
    d2 = np.einsum("ni,ni->n", e, np.linalg.solve(P, e[..., None])[..., 0])
    says = np.isin(np.asarray(statuses[start:]), LOST_STATUSES)
    return int(lost.sum()), int((lost & (says | (d2 <= 9.0))).sum())


def on_wrong_twin(means: np.ndarray, poses: np.ndarray, city: Any) -> np.ndarray:
    """Per frame (n,) bool: the reported position lies within ``TWIN_RADIUS`` of a twin of
    the true one and more than ``LOST_ERROR`` from the truth."""
    out = np.zeros(len(means), dtype=bool)
    for t, (m, p) in enumerate(zip(means, poses)):
        twins = p[:2] + city.twin_shifts(p[:2])
        out[t] = bool(len(twins) and np.min(np.hypot(*(twins - m[:2]).T)) < TWIN_RADIUS
                      and np.hypot(*(m[:2] - p[:2])) > LOST_ERROR)
    return out


def longest_run(flags: np.ndarray) -> int:
    """Length of the longest stretch of True in ``flags`` (n,)."""
    best = run = 0
    for f in flags:
        run = run + 1 if f else 0
        best = max(best, run)
    return best


def wrong_twin_run(means: np.ndarray, poses: np.ndarray, city: Any, start: int,
                   statuses: list[str] | None = None) -> int:
    """Longest run of frames from ``start`` with the belief committed to a wrong twin: its
    report on a wrong twin (:func:`on_wrong_twin`) while its status (when ``statuses`` are
    given) claims to know, i.e. is not one of :data:`LOST_STATUSES`. Without ``statuses``:
    the report on a wrong twin whatever the status says."""
    flags = on_wrong_twin(means[start:], poses[start:], city)
    if statuses is not None:
        flags &= ~np.isin(np.asarray(statuses[start:]), LOST_STATUSES)
    return longest_run(flags)


def truth_kept(hypotheses: list[dict[str, np.ndarray]], poses: np.ndarray,
               flags: np.ndarray) -> tuple[int, int]:
    """(frames flagged, of them frames with a hypothesis mean within ``LOST_ERROR`` of the
    true position): does the belief keep the true twin while it reports a wrong one?"""
    kept = sum(bool(np.any(np.hypot(*(h["means"][:, :2] - p[:2]).T) < LOST_ERROR))
               for h, p, f in zip(hypotheses, poses, flags) if f)
    return int(flags.sum()), int(kept)


def nees(means: np.ndarray, covs: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Per-frame NEES (n,) with the heading residual wrapped."""
    e = poses - means
    e[:, 2] = wrap_angle(e[:, 2])
    return np.einsum("ni,ni->n", e, np.linalg.solve(covs, e[..., None])[..., 0])


# ---------------------------------------------------------------- stages
def make_env(args: GlobalBenchConfig, city: int, layout: str = "random") -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, city_layout=layout,
                    image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def fit(env: gym.Env, args: GlobalBenchConfig) -> Any:
    with warnings.catch_warnings():  # GSE's eigen-gap warning on a thin tube of poses
        warnings.filterwarnings("ignore", category=RuntimeWarning, module="localization")
        loc, _ = fit_city_localizer(
            env, n_train=args.n_train, lanes="streets", n_drive=args.n_drive, seed=args.seed,
            localizer_params={"features_params": {"n_components": args.n_components}},
            calibrate_on_belief=False, measurements=("representation",))
    return loc


def kidnaps(env: gym.Env, loc: Any, args: GlobalBenchConfig, n: int, seed: int,
            bar: tqdm) -> dict[str, list[dict[str, Any]]]:
    """Per filter, one record per kidnap drive: steps to recover, lost / admitted steps,
    the longest wrong-twin run (look-alike cities)."""
    mm, city = env.unwrapped.motion_model, env.unwrapped.city
    out: dict[str, list[dict[str, Any]]] = {f: [] for f in args.filter_list()}
    for k in range(n):
        drive = ke.record_kidnap_drive(env, loc, args.steps_before, args.steps_after, seed + k)
        for name, recs in out.items():
            hyps: list[dict[str, np.ndarray]] = []
            means, covs, statuses = ke.run_filter(name, drive, loc, mm, seed + k,
                                                  hypotheses=hyps)
            lost, said = admitted(means, covs, statuses, drive.poses, drive.kidnap)
            rec = {"steps": ke.steps_to_recover(means, drive.poses, drive.kidnap),
                   "lost_steps": lost, "admitted_steps": said}
            if hasattr(city, "twin_shifts"):
                rec.update(twin_scores(means, statuses, hyps, drive, city))
            recs.append(rec)
        bar.update()
    return out


def twin_scores(means: np.ndarray, statuses: list[str], hypotheses: list[dict[str, np.ndarray]],
                drive: Any, city: Any) -> dict[str, int]:
    """Look-alike scores of one drive from its kidnap on: the longest run committed to a
    wrong twin, the longest run reported on one (any status), and the frames reported on a
    wrong twin with / without a hypothesis at the truth."""
    k = drive.kidnap
    flags = on_wrong_twin(means[k:], drive.poses[k:], city)
    frames, kept = truth_kept(hypotheses[k:], drive.poses[k:], flags)
    return {"wrong_twin_run": wrong_twin_run(means, drive.poses, city, k, statuses),
            "twin_report_run": longest_run(flags), "twin_frames": frames, "twin_kept": kept}


def nominal(env: gym.Env, loc: Any, args: GlobalBenchConfig, seed: int,
            bar: tqdm) -> dict[str, list[dict[str, float]]]:
    """Per filter, per nominal drive: squared errors, NEES and ms per step (one core)."""
    mm = env.unwrapped.motion_model
    out: dict[str, list[dict[str, float]]] = {f: [] for f in args.filter_list()}
    for k in range(args.n_nominal):
        drive = ke.record_kidnap_drive(env, loc, args.nominal_steps, 0, seed + k)
        for name, recs in out.items():
            with threadpool_limits(1):
                t0 = time.perf_counter()
                means, covs, _ = ke.run_filter(name, drive, loc, mm, seed + k)
                ms = 1e3 * (time.perf_counter() - t0) / len(drive.controls)
            err2 = np.sum((means[:, :2] - drive.poses[:, :2]) ** 2, axis=1)
            recs.append({"sse": float(err2.sum()), "n": len(err2), "ms_per_step": ms,
                              "nees_mean": float(np.mean(nees(means, covs, drive.poses)))})
        bar.update()
    return out


# ---------------------------------------------------------------- summaries
def _split(n: int, parts: int) -> list[int]:
    return [n // parts + (i < n % parts) for i in range(parts)]


def summarize_kidnaps(recs: list[dict[str, Any]]) -> dict[str, float]:
    s = np.array([np.inf if r["steps"] is None else r["steps"] for r in recs], dtype=float)
    lost = sum(r["lost_steps"] for r in recs)
    out = {"n": len(recs), "recovered_within_30": float(np.mean(s <= WITHIN)),
           "median_steps": float(np.median(s)) if len(s) else float("nan"),
           "p95_steps": float(np.percentile(s, 95, method="higher")) if len(s) else float("nan"),
           "lost_steps": int(lost),
           "admitted_while_lost": sum(r["admitted_steps"] for r in recs) / lost if lost
           else float("nan")}
    if recs and "wrong_twin_run" in recs[0]:
        frames = sum(r["twin_frames"] for r in recs)
        out.update({
            "wrong_twin_runs": float(np.mean([r["wrong_twin_run"] > WRONG_TWIN_STEPS
                                              for r in recs])),
            "twin_report_runs": float(np.mean([r["twin_report_run"] > WRONG_TWIN_STEPS
                                               for r in recs])),
            "twin_frames": int(frames),
            "twin_kept": sum(r["twin_kept"] for r in recs) / frames if frames else float("nan")})
    return out


def summarize_nominal(recs: list[dict[str, float]]) -> dict[str, float]:
    d = len(recs)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * d) / d
    return {"drives": d, "rmse": float(np.sqrt(sum(r["sse"] for r in recs) /
                                               sum(r["n"] for r in recs))),
            "nees_mean": float(np.mean([r["nees_mean"] for r in recs])),
            "nees_band": [float(lo), float(hi)],
            "ms_per_step": float(np.mean([r["ms_per_step"] for r in recs]))}


def run_global_bench(args: GlobalBenchConfig) -> dict[str, Any]:
    """Run the benchmark; write ``bench_global.json`` / ``.md``; return the result."""
    args = args.resolved()
    cities, names = args.city_list(), args.filter_list()
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    kid: dict[str, list] = {n: [] for n in names}
    nom: dict[str, list] = {n: [] for n in names}
    glob: list = []
    agent_runs: dict[str, list] = {n: [] for n in names}
    work = args.n_kidnaps + args.n_nominal * len(cities) + args.n_lookalike + (
        len(names) * len(cities) if args.agent_episodes else 0)
    with tqdm(total=work, desc="bench global", leave=False) as bar:
        for i, (city, n_kid, n_glob) in enumerate(zip(cities, _split(args.n_kidnaps, len(cities)),
                                                       _split(args.n_global, len(cities)))):
            env = make_env(args, city)
            loc = fit(env, args)
            base = args.seed + 10_000 * (i + 1)
            for n, recs in kidnaps(env, loc, args, n_kid, base, bar).items():
                kid[n] += recs
            for n, recs in nominal(env, loc, args, base + 5_000, bar).items():
                nom[n] += recs
            if "particles" in names and n_glob:
                g = ke.evaluate_global(env, loc, n_glob, args.global_steps, base + 7_000, WITHIN)
                glob += g["steps"]
            if args.agent_episodes:
                runs = ga.kidnapped_episodes(
                    loc, city, names, args.agent_episodes, base + 8_000, args.agent_kidnap_at,
                    args.agent_max_steps, args.image_size, args.motion_noise, bar)
                for n, eps in runs.items():
                    agent_runs[n] += eps
            env.close()
        env = make_env(args, args.lookalike_city, "lookalike")
        loc = fit(env, args)
        look = kidnaps(env, loc, args, args.n_lookalike, args.seed + 90_000, bar)
        env.close()
    g_steps = np.array([np.inf if k is None else k for k in glob], dtype=float)
    summary = {n: {"kidnap": summarize_kidnaps(kid[n]), "nominal": summarize_nominal(nom[n]),
                   "lookalike": summarize_kidnaps(look[n]),
                   "agents": summarize(agent_runs[n]) if agent_runs[n] else None,
                   "global": None if n != "particles" or not glob else
                   {"n": len(glob), "recovered_within_30": float(np.mean(g_steps <= WITHIN)),
                    "median_steps": float(np.median(g_steps))}} for n in names}
    result = {"args": dataclasses.asdict(args), **provenance(),
              "seconds": time.perf_counter() - t0, "filters": names, "targets": TARGETS,
              "summary": summary, "kidnap_runs": kid, "lookalike_runs": look,
              "nominal_runs": nom, "global_steps": glob,
              "agent_runs": {n: [dataclasses.asdict(e) for e in r] for n, r in agent_runs.items()},
              "setup": f"cities {args.cities}, look-alike city {args.lookalike_city}, "
                       f"{args.image_size}x{args.image_size} images, motion noise "
                       f"{args.motion_noise}, PixelPCA({args.n_components}) on {args.n_train} "
                       f"street images per city"}
    (out / "bench_global.json").write_text(json.dumps(result, indent=2, default=_json))
    (out / "bench_global.md").write_text(markdown(result))
    print(markdown(result))
    return result


def _json(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")
