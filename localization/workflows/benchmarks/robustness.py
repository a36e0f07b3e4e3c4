"""Robustness rows of the agents (issue 17): every agent on every pose source, nominal, with one
kidnap per episode, under each appearance preset and with moving vehicles
(``appearance-nav bench --only robustness``; its options are ``--robustness-<option>``).

    appearance-nav bench --only robustness --robustness-workers 2
    appearance-nav bench --only robustness --robustness-quick      # smoke run

On each held-out city of ``cities`` (21, 22: never used to choose a default) two street-wide
localizers are fitted (:func:`~localization.workflows.tracking.fit_city_localizer`):
"daylight" on today's look, over the whole street surface at every heading
(``daylight_lanes="free"``, 40000 images: on tuning cities 13-16 a robot pushed off its lane
was brought back by its own images, 0.99 success against 0.94 on the lanes' tube,
``"streets"``), with ``daylight_features``: by default the
packaged SmallCNN of random views of other cities on the whole image; on tuning cities 13-16,
600 episodes per row, the scripted agent on the EKF reached 1.000 of its goals nominal and
0.95 kidnapped, against 0.990 and 0.860 with PixelPCA, docs/benchmarks.md §11) and
"randomised" for the presets: the packaged condition-randomised SmallCNN (on tuning city 11
PixelPCA's single-image median error there was 5.0 m, the SmallCNN's 0.30 m, in daylight),
its noise and calibration drives under ``conditions="random"``, its map one per look
(``randomised_map="experiences"``, an
:class:`~localization.experiences.ExperienceLocalizer` of daylight and a draw of each other
lighting family: on tuning cities 13-14 the scripted agent on the EKF reached 1.00 of its
goals under dusk, night, seasonal colours, overcast and exposure, 12 episodes each; with
one daylight map 0.67-1.00, with a map of images each in its own look 0.25-0.67,
docs/benchmarks.md §11). Then every
(agent, pose source, condition) row runs ``episodes`` episodes per city from lane starts to
random goals, the same reset seeds in every row:

* conditions: ``nominal``, ``kidnap`` (one unannounced kidnap at step ``kidnap_at``,
  :class:`envs.kidnapping.KidnapWrapper`) and ``push`` (at that step the robot is shoved
  0.8-1.6 m sideways off its lane and turned by up to 0.5 rad, unannounced:
  ``KidnapWrapper(push=PUSH_DISTANCE)``) on the daylight localizer; each appearance preset
  of :data:`envs.conditions.PRESETS` (``traffic``: moving vehicles and pedestrians, a
  collision hazard) on the randomised localizer (``moving_localizer="daylight"``: traffic
  on the daylight one);
* pose sources: ``oracle`` (true pose), ``ekf`` and ``particles`` (the GSE belief with either
  filter) and ``dead_reckoning``; the oracle and dead reckoning never see an image, so under
  the lighting and camera presets their episodes would equal the nominal ones and are not
  run again (the table says "as nominal"); with moving things they are;
* agents: the scripted navigator (it slows down on a doubtful belief and stops to look
  around while lost: :class:`agents.scripted.ScriptedAgent`) and, with ``oracle_policy`` and
  ``belief_policy``, PPO (the policy trained on the true pose on the oracle, the one trained
  on the belief on the other sources).

The episodes are split into tasks by (city, condition, source, agent, seeds) and run by
:func:`~localization.workflows.parallel.map_tasks` (``workers`` local processes or Ray); an
episode depends only on its settings and reset seed, so the results equal the serial run's.
Writes ``<out>/bench_robustness.json`` and ``.md`` (metrics of
:func:`agents.evaluation.summarize`, each with its standard error).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np

from agents.evaluation import Episode, as_records, run_episodes, summarize
from agents.scripted import ScriptedAgent
from agents.sources import make_pose_env
from envs.kidnapping import PUSH_DISTANCE
from localization.loading import load_localizer
from localization.localizer import AppearanceLocalizer
from localization.workflows.benchmarks.appearance import fit_looks, training_looks
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.benchmarks.robustness_config import (
    AGENTS,
    FILTERS,
    KIDNAPS,
    SOURCES,
    SPECIAL,
    RobustnessConfig,
    runs_condition,
    training_of,
)
from localization.workflows.benchmarks.robustness_report import (
    DEFAULT_STEPS,
    MOVING,
    markdown,
    targets,
)
from localization.workflows.benchmarks.street_features import localizer_features
from localization.workflows.parallel import map_tasks, worker_env

__all__ = [
    "AGENTS",
    "FILTERS",
    "SOURCES",
    "RobustTask",
    "RobustnessConfig",
    "run_robust_task",
    "run_robustness_bench",
]


def localizer_path(args: RobustnessConfig, city: int, training: str) -> Path:
    """Where a city's localizer of a training is saved (a free daylight one apart)."""
    free = "_free" if training == "daylight" and args.daylight_lanes == "free" else ""
    return Path(args.out_dir) / "robustness" / f"localizer_{city}_{training}{free}.npz"


def localizer_params(args: RobustnessConfig, training: str) -> dict[str, Any] | None:
    """:class:`AppearanceLocalizer` settings of a training: the daylight localizer's
    ``daylight_features`` (:func:`.street_features.localizer_features`); the randomised one's
    defaults, or with ``randomised_features="small_cnn"`` the condition-randomised SmallCNN."""
    if training == "daylight":
        return localizer_features(args.daylight_features, "perspective", 64)
    if args.randomised_features == "pixel_pca":
        return None
    from localization.features.weights import small_cnn_weights

    weights = small_cnn_weights("perspective", "conditions")
    return {"features": "small_cnn", "features_params": {"n_components": 64,
                                                         "weights": str(weights)}}


@dataclass(frozen=True)
class FitTask:
    """One localizer to fit and save."""

    config: RobustnessConfig
    city: int
    training: str


def _fit_env(args: RobustnessConfig, city: int, conditions: Any) -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, conditions=conditions,
                    image_size=(args.image_size, args.image_size), motion_noise=args.motion_noise,
                    max_episode_steps=None)


def run_fit_task(task: FitTask) -> float:
    """Fit the task's street-wide localizer, save it; return the seconds taken."""
    args, t0 = task.config, time.perf_counter()
    daylight = task.training == "daylight"
    map_looks, looks = training_looks(task.training, args.randomised_map)
    loc = fit_looks(lambda c: _fit_env(args, task.city, c), task.city, map_looks, looks,
                    n_train=args.n_train if daylight else args.n_train_randomised,
                    lanes=args.daylight_lanes if daylight else "streets",
                    n_drive=args.n_drive, seed=task.city,
                    localizer_params=localizer_params(args, task.training))
    path = localizer_path(args, task.city, task.training)
    path.parent.mkdir(parents=True, exist_ok=True)
    loc.save(path)
    return time.perf_counter() - t0


@dataclass(frozen=True)
class RobustTask:
    """The episodes of one agent on one pose source under one condition in one city."""

    config: RobustnessConfig
    city: int
    condition: str
    source: str
    agent: str
    seeds: tuple[int, ...]


_LOCALIZERS: dict[Path, AppearanceLocalizer] = {}  # this worker's city's two localizers


def _localizer(args: RobustnessConfig, city: int, condition: str) -> AppearanceLocalizer:
    path = localizer_path(args, city, training_of(condition, args.moving_localizer))
    if path not in _LOCALIZERS:
        if len(_LOCALIZERS) >= 2:  # a city's daylight and randomised localizers
            _LOCALIZERS.clear()
        _LOCALIZERS[path] = load_localizer(path)
    return _LOCALIZERS[path]


def make_env(args: RobustnessConfig, city: int, condition: str, source: str) -> gym.Env:
    """The pose env of one row: ``source`` under ``condition`` in ``city``."""
    loc = None if source == "oracle" else _localizer(args, city, condition)
    return make_pose_env("belief" if source in FILTERS else source, loc, scene_seed=city,
                         image_size=(args.image_size, args.image_size),
                         motion_noise=args.motion_noise, max_episode_steps=args.max_steps,
                         kidnap_at=(args.kidnap_at,) if condition in KIDNAPS else (),
                         kidnap_push=PUSH_DISTANCE if condition == "push" else None,
                         conditions=None if condition in SPECIAL else condition,
                         **belief_options(args, source, condition))


def belief_options(args: RobustnessConfig, source: str, condition: str = "nominal"
                   ) -> dict[str, Any]:
    """The BeliefWrapper settings of a row's pose source under ``condition`` (none for the
    image-free ones). ``detect_divergence`` applies to the EKF rows on a localizer of one
    map: the randomised localizer of experiences has several, which the monitor refuses."""
    if source not in FILTERS:
        return {}
    options: dict[str, Any] = {"filter": FILTERS[source], "image_pose": args.guard}
    one_map = (training_of(condition, args.moving_localizer) == "daylight"
               or args.randomised_map != "experiences")
    familiar = args.particle_familiar_novelty if source == "particles" else args.familiar_novelty
    if familiar > 0 and one_map:
        options["familiar_novelty"] = familiar
    if source == "ekf" and args.detect_divergence and one_map:
        detect = {"offset_doubt": args.offset_doubt} if args.offset_doubt > 0 else True
        options["filter_options"] = {"detect_divergence": detect}
    if source == "particles":
        extra: dict[str, Any] = {}
        if args.particle_unmapped != "floor":
            extra["unmapped"] = args.particle_unmapped
        if args.particle_offset_doubt > 0:
            extra["track_mode"] = {"offset_doubt": args.particle_offset_doubt}
        if extra:
            options["filter_options"] = extra
    return options


def make_agent(args: RobustnessConfig, agent: str, source: str, city: Any) -> Any:
    """The scripted navigator, or the PPO policy trained on the row's kind of pose."""
    if agent == "scripted":
        patience, agree, memory = guard_settings(args, source)
        return ScriptedAgent(city, guard=args.guard and source in FILTERS,
                             slow_steps=args.slow_steps or None, guard_patience=patience,
                             guard_agree=agree, guard_memory=memory)
    from agents.ppo import PPOAgent

    return PPOAgent.load(policy_path(args, source), city)


def guard_settings(args: RobustnessConfig, source: str
                   ) -> tuple[int | None, float | None, int]:
    """The scripted agent's guard patience, agreement radius and memory on a row's pose
    source (None: never yields, whatever the belief; 0: the latest image only)."""
    if source == "particles":
        return (args.particle_guard_patience or None, args.particle_guard_agree or None,
                args.particle_guard_memory)
    return args.guard_patience or None, args.guard_agree or None, args.guard_memory


def policy_path(args: RobustnessConfig, source: str) -> Path:
    return Path(args.oracle_policy if source == "oracle" else args.belief_policy)


def run_robust_task(task: RobustTask) -> list[Episode]:
    """Run the task's episodes (the env kept while the next task shares it). The records are
    also written to :func:`task_path`, so that a run that stops early resumes there."""
    args = task.config
    key = (dataclasses.astuple(dataclasses.replace(args, workers=1, ray_address="")),
           task.city, task.condition, task.source)
    env = worker_env(key, lambda: make_env(args, task.city, task.condition, task.source))
    agent = make_agent(args, task.agent, task.source, env.unwrapped.city)
    runs = run_episodes(env, agent, task.seeds, progress=False)
    path = task_path(task)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(as_records(runs)))
    return runs


def task_path(task: RobustTask) -> Path:
    """Where a task's episode records go (``<out>/robustness/episodes/``)."""
    options = belief_options(task.config, task.source, task.condition)
    extra = options.get("filter_options", {})
    name = (f"{task.agent}_{task.source}_{task.condition}_{task.city}_{task.seeds[0]}-"
            f"{task.seeds[-1]}_{task.config.image_size}px_{task.config.max_steps}"
            f"{_filter_marks(extra)}"
            f"{_familiar_mark(options)}"
            f"{'_guard' if options.get('image_pose') and task.agent == 'scripted' else ''}"
            f"{_agent_marks(task)}"
            f"{_on_daylight(task)}.json")
    return Path(task.config.out_dir) / "robustness" / "episodes" / name


def _familiar_mark(options: dict[str, Any]) -> str:
    """A file-name mark of a row whose belief reports unfamiliar images as doubtful."""
    return f"_familiar{options['familiar_novelty']:g}" if "familiar_novelty" in options else ""


def _filter_marks(filter_options: dict[str, Any]) -> str:
    """File-name marks of a row's filter options: the EKF's divergence monitor (and its
    offset test), the particles' unmapped score and their tracker's offset test."""
    detect = filter_options.get("detect_divergence")
    marks = "" if detect is None else "_detect" + (
        f"-offset{detect['offset_doubt']:g}" if isinstance(detect, dict) else "")
    if "unmapped" in filter_options:
        marks += f"_unmapped-{filter_options['unmapped']}"
    if "track_mode" in filter_options:
        marks += f"_offset{filter_options['track_mode']['offset_doubt']:g}"
    return marks


def _agent_marks(task: RobustTask) -> str:
    """File-name marks of the scripted agent's bound on slow steps, its guard's patience
    and memory (none: unbounded, never yields, the latest image only)."""
    if task.agent != "scripted":
        return ""
    steps = task.config.slow_steps
    patience, agree, memory = guard_settings(task.config, task.source)
    guarded = task.config.guard and task.source in FILTERS
    yields = guarded and patience is not None
    return ((f"_slow{steps}" if steps else "") + (f"_yield{patience}" if yields else "")
            + (f"-agree{agree:g}" if yields and agree is not None else "")
            + (f"_memory{memory}" if guarded and memory else ""))


def _on_daylight(task: RobustTask) -> str:
    """A file-name mark of a row with moving things on the daylight localizer."""
    moving = task.condition in MOVING and task.source != "oracle"
    return "_daylight" if moving and task.config.moving_localizer == "daylight" else ""


def load_task(task: RobustTask) -> list[Episode] | None:
    """A finished task's episodes from an earlier run with ``reuse_localizers`` (the same
    localizers), or None."""
    path = task_path(task)
    if not (task.config.reuse_localizers and path.exists()):
        return None
    names = {f.name for f in dataclasses.fields(Episode)}
    try:
        return [Episode(**{k: v for k, v in r.items() if k in names})
                for r in json.loads(path.read_text())]
    except (ValueError, TypeError) as err:
        raise ValueError(f"{path} is not a task's episode records ({err}); delete it") from None


def _rows(args: RobustnessConfig, names: dict[str, list[str]]) -> list[tuple[str, str, str]]:
    """The (agent, source, condition) rows to run (PPO only with both policies)."""
    agents = [a for a in names["agents"] if a != "ppo" or (
        args.oracle_policy and args.belief_policy)]
    if "ppo" in names["agents"] and "ppo" not in agents:
        print("robustness: no PPO rows (give --robustness-oracle-policy and "
              "--robustness-belief-policy)")
    return [(a, s, c) for a in agents for c in names["conditions"] for s in names["sources"]
            if runs_condition(s, c)]


def trainings_used(rows: list[tuple[str, str, str]], moving: str = "randomised") -> list[str]:
    """The localizers (:func:`training_of`) the (agent, source, condition) rows use: the true
    pose needs none, dead reckoning a localizer's process noise."""
    return sorted({training_of(c, moving) for _, s, c in rows if s != "oracle"})


def _fit_all(args: RobustnessConfig, cities: list[int], rows: list[tuple[str, str, str]]
             ) -> float:
    trainings = trainings_used(rows, args.moving_localizer)
    fits = [FitTask(args, city, t) for city in cities for t in trainings
            if not (args.reuse_localizers and localizer_path(args, city, t).exists())]
    seconds = map_tasks(run_fit_task, fits, workers=args.workers, ray_address=args.ray_address,
                        desc=f"localizers ({len(fits)})")
    return float(sum(seconds))


def _summary(runs: list[Episode]) -> dict[str, float]:
    """:func:`summarize` with ``success_within_default``: the share of episodes that reached
    the goal within :data:`DEFAULT_STEPS` (an episode runs the same up to its truncation)."""
    out = summarize(runs)
    p = float(np.mean([e.success and e.steps <= DEFAULT_STEPS for e in runs]))
    out["success_within_default"] = p
    out["success_within_default_se"] = float(np.sqrt(p * (1 - p) / len(runs)))
    return out


def run_robustness_bench(args: RobustnessConfig) -> dict[str, Any]:
    """Fit the localizers, run every row, write ``bench_robustness.json`` / ``.md``; return
    the result."""
    args = args.resolved()
    names = args.lists()
    cities = [int(c) for c in names["cities"]]
    t0 = time.perf_counter()
    rows = _rows(args, names)
    fit_seconds = _fit_all(args, cities, rows)
    seeds = tuple(range(args.seed, args.seed + args.episodes))
    chunk = max(1, -(-len(seeds) // 2))  # two tasks per row and city: both workers stay busy
    tasks = [RobustTask(args, city, c, s, a, seeds[i:i + chunk]) for a, s, c in rows
             for city in cities for i in range(0, len(seeds), chunk)]
    done = {i: runs for i, t in enumerate(tasks) if (runs := load_task(t)) is not None}
    todo = [t for i, t in enumerate(tasks) if i not in done]
    fresh = iter(map_tasks(run_robust_task, todo, workers=args.workers,
                           ray_address=args.ray_address,
                           desc=f"episodes ({len(todo)} tasks, {len(done)} done before)"))
    results = [done[i] if i in done else next(fresh) for i in range(len(tasks))]
    episodes: dict[str, list[Episode]] = {"/".join(r): [] for r in rows}
    for task, runs in zip(tasks, results):
        episodes[f"{task.agent}/{task.source}/{task.condition}"] += runs
    summary = {key: _summary(runs) for key, runs in episodes.items()}
    result = {"args": dataclasses.asdict(args), **provenance(),
              "fit_seconds": round(fit_seconds, 1),
              "seconds": round(time.perf_counter() - t0, 1), "summary": summary,
              "targets": targets(summary, args.moving_localizer),
              "episodes": {k: as_records(v) for k, v in episodes.items()}}
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_robustness.json").write_text(json.dumps(result, indent=1))
    md = markdown(result)
    (out / "bench_robustness.md").write_text(md)
    print(md)
    return result
