"""Benchmarks: speed and accuracy targets measured side by side, each writing JSON and a
markdown table (``make bench`` runs them all).

    appearance-nav bench                                   # env, gse, filter, agents
    appearance-nav bench --only gse,filter --gse-quick --filter-quick
    appearance-nav bench --only env --no-env-cameras --env-sizes 64

- env: AppearanceNav-v0 steps/s against a raw MuJoCo step+render loop
  (``<env-out-dir>/bench_env.json`` / ``.md``);
- gse: GSERegressor fit time, memory and query latency vs n, accuracy against KNR and
  retrieval (``<gse-out>.json`` / ``.md``);
- filter: BeliefWrapper's per-step cost and closed-loop tracking accuracy
  (``<filter-out-dir>/bench_filter.json`` / ``.md``);
- agents: PPO on the belief against PPO on the true pose, same budget (needs the localizer
  ``make demo`` writes; ``<agents-out>/bench_agents.json`` / ``.md``);
- global: kidnapping recovery, global start, the look-alike city, nominal tracking and cost
  of the pose filters side by side (``<global-out-dir>/bench_global.json`` / ``.md``);
- appearance: single-image and closed-loop localization under every conditions preset, for
  a localizer trained on daylight and one on randomised conditions
  (``<appearance-out-dir>/bench_appearance.json`` / ``.md``);
- coverage: single-image and closed-loop localization anywhere on the street surface at any
  heading, GSE against KNR and retrieval (``<coverage-out-dir>/bench_coverage.json`` / ``.md``);
- parallel: dataset collection on one process, on local worker processes and on Ray tasks,
  side by side (``<parallel-out-dir>/bench_parallel.json`` / ``.md``);
- city60: closed-loop tracking and the scripted agent on held-out 60 m cities (nine times the
  default area; ``<city60-out-dir>/bench_city60.json`` / ``.md``);
- robustness: the scripted agent (and PPO with ``--robustness-oracle-policy`` / ``--robustness-belief-policy``) on every pose source,
  nominal, kidnapped, under each appearance preset and among moving vehicles, with success,
  SPL, collisions, time to goal and belief RMSE (``<robustness-out-dir>/bench_robustness.*``).

Each benchmark's own options are ``--<benchmark>-<option>`` (listed below); they are checked
for every benchmark chosen by ``--only`` before the first one starts.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import localization.workflows.sim  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
from localization.cli._args import (
    UsageError,
    check_choice,
    check_choices,
    check_env,
    check_existing_file,
    check_int_list,
    check_numbers,
    check_output_dir,
    check_output_file,
)
from localization.filtering.belief import NOISE_MODELS
from localization.gse.first_order import FIRST_ORDER
from localization.workflows.benchmarks import BENCHMARKS, benchmark
from localization.workflows.benchmarks.agents import AgentsBenchConfig
from localization.workflows.benchmarks.appearance_config import FEATURES as APPEARANCE_FEATURES
from localization.workflows.benchmarks.appearance_config import (
    MAP_CAMERAS,
    RANDOMISED_MAPS,
    TRAININGS,
    AppearanceBenchConfig,
)
from localization.workflows.benchmarks.city60 import City60BenchConfig
from localization.workflows.benchmarks.coverage import CoverageBenchConfig
from localization.workflows.benchmarks.env import EnvBenchConfig
from localization.workflows.benchmarks.filter import FilterBenchConfig
from localization.workflows.benchmarks.global_loc import GlobalBenchConfig
from localization.workflows.benchmarks.gse import GSEBenchConfig
from localization.workflows.benchmarks.noise_models import NoiseBenchConfig
from localization.workflows.benchmarks.parallel import ParallelBenchConfig
from localization.workflows.benchmarks.robustness_config import AGENTS as ROBUST_AGENTS
from localization.workflows.benchmarks.robustness_config import (
    DAYLIGHT_LANES,
    SPECIAL,
    RobustnessConfig,
)
from localization.workflows.benchmarks.robustness_config import SOURCES as ROBUST_SOURCES
from localization.workflows.benchmarks.street_features import FEATURES as STREET_FEATURES
from localization.workflows.kidnap_eval import FILTERS
from localization.workflows.parallel import check_ray_address
from localization.workflows.sim import (
    CAMERAS,
    CONDITION_NAMES,
    LANE_SETS,
    MODES,
    NORMALIZATIONS,
    check_city_layout,
)
from localization.workflows.training import VEC_ENVS

__all__ = ["Args", "check", "run"]


@dataclass
class Args:
    """Which benchmarks run, and the options of each."""

    only: str = field(default=",".join(BENCHMARKS), metadata={
        "help": "comma-separated benchmarks to run: " + ", ".join(BENCHMARKS)})
    env: EnvBenchConfig = field(default_factory=lambda: EnvBenchConfig(cameras=True),
                                metadata={"help": "env steps/s vs raw MuJoCo"})
    gse: GSEBenchConfig = field(default_factory=GSEBenchConfig, metadata={
        "help": "GSE fit time, memory, latency and accuracy"})
    filter: FilterBenchConfig = field(default_factory=FilterBenchConfig, metadata={
        "help": "belief wrapper cost and tracking accuracy"})
    agents: AgentsBenchConfig = field(default_factory=AgentsBenchConfig, metadata={
        "help": "PPO on the belief vs on the true pose"})
    global_: GlobalBenchConfig = field(default_factory=GlobalBenchConfig, metadata={
        "help": "kidnapping, global start, look-alike city: the filters side by side"})
    appearance: AppearanceBenchConfig = field(default_factory=AppearanceBenchConfig, metadata={
        "help": "localization under lighting, weather, camera effects and traffic"})
    coverage: CoverageBenchConfig = field(default_factory=CoverageBenchConfig, metadata={
        "help": "localization anywhere on the streets at any heading, off-lane drives"})
    parallel: ParallelBenchConfig = field(default_factory=ParallelBenchConfig, metadata={
        "help": "collection on one process, local processes and Ray, side by side"})
    noise: NoiseBenchConfig = field(default_factory=NoiseBenchConfig, metadata={
        "help": "global against heteroscedastic measurement noise R under each condition"})
    city60: City60BenchConfig = field(default_factory=City60BenchConfig, metadata={
        "help": "tracking and the scripted agent on 60 m cities (nine times the default area)"})
    robustness: RobustnessConfig = field(default_factory=RobustnessConfig, metadata={
        "help": "agents on every pose source: nominal, kidnapped, each preset, moving things"})


def _check_env_bench(c: EnvBenchConfig) -> None:
    check_int_list("env_sizes", c.sizes, minimum=1)
    if c.conditions.strip():
        check_choices("env_conditions", c.conditions, CONDITION_NAMES)
    check_numbers(c, positive=("steps", "chunk"), non_negative=("warmup", "scene_seed", "seed"),
                  prefix="env_")
    check_output_dir("env_out_dir", c.out_dir)


def _check_gse_bench(c: GSEBenchConfig) -> None:
    check_int_list("gse_ns", c.ns, minimum=2)
    check_int_list("gse_accuracy_dims", c.accuracy_dims, minimum=1)
    check_int_list("gse_scale_ns", c.scale_ns, minimum=100)
    check_numbers(c, positive=("m", "n_neighbors", "batch_size", "latency_repeats", "latency_n",
                               "accuracy_n_train", "accuracy_n_test", "timeout", "compare_n",
                               "incremental_n", "incremental_new"),
                  non_negative=("seed", "map_seed", "threads"), prefix="gse_")
    if c.out:
        check_output_file("gse_out", str(Path(c.out).with_suffix(".json")))


def _check_filter_bench(c: FilterBenchConfig) -> None:
    check_env(c, prefix="filter_")
    check_numbers(c, positive=("n_train", "n_train_dcnn", "n_drive", "steps", "runs",
                               "overhead_steps", "chunk"), non_negative=("seed",),
                  prefix="filter_")
    check_output_dir("filter_out_dir", c.out_dir)


def _check_agents_bench(c: AgentsBenchConfig) -> None:
    check_int_list("agents_eval_cities", c.eval_cities, minimum=0)
    if c.train_kidnap_at:
        check_int_list("agents_train_kidnap_at", c.train_kidnap_at, minimum=0)
    check_choice("agents_vec_env", c.vec_env, VEC_ENVS)
    check_numbers(c, positive=("total_timesteps", "eval_freq", "n_envs", "episodes", "n_train",
                               "n_components", "n_drive", "active_episodes", "workers"),
                  non_negative=("seed", "train_city", "first_seed", "active_penalty",
                                "kidnap_step", "motion_noise", "active_timesteps"),
                  prefix="agents_")
    check_output_dir("agents_localizers", c.localizers)
    check_output_dir("agents_out", c.out)


def _check_global_bench(c: GlobalBenchConfig) -> None:
    check_int_list("global_cities", c.cities, minimum=0)
    check_choices("global_filters", c.filters, FILTERS)
    check_numbers(c, positive=("image_size", "n_train", "n_drive", "n_components", "n_kidnaps",
                               "steps_before", "steps_after", "global_steps", "n_lookalike",
                               "n_nominal", "nominal_steps"),
                  non_negative=("lookalike_city", "motion_noise", "n_global", "seed"),
                  prefix="global_")
    check_output_dir("global_out_dir", c.out_dir)


def _check_appearance_bench(c: AppearanceBenchConfig) -> None:
    check_int_list("appearance_cities", c.cities, minimum=0)
    check_choices("appearance_conditions", c.conditions, CONDITION_NAMES)
    check_choices("appearance_trainings", c.trainings, TRAININGS)
    check_choices("appearance_smooth_trainings", c.smooth_trainings, TRAININGS)
    check_choice("appearance_normalize", c.normalize, NORMALIZATIONS)
    check_choice("appearance_features", c.features, APPEARANCE_FEATURES)
    check_choice("appearance_lanes", c.lanes, LANE_SETS)
    check_choice("appearance_randomised_map", c.randomised_map, RANDOMISED_MAPS)
    check_choice("appearance_map_camera", c.map_camera, MAP_CAMERAS)
    if c.map_camera == "random" and c.randomised_map == "random":
        raise UsageError("appearance_map_camera", "random needs fixed looks "
                         "(--appearance-randomised-map experiences or default): the random "
                         "map already draws each image's camera")
    check_choice("appearance_first_order", c.first_order, FIRST_ORDER)
    check_choice("appearance_noise", c.noise, NOISE_MODELS)
    if c.noise_trainings.strip():
        check_choices("appearance_noise_trainings", c.noise_trainings, TRAININGS)
    if c.novelty_noise.strip():
        check_choices("appearance_novelty_noise", c.novelty_noise, ("daylight",))
    check_numbers(c, positive=("image_size", "n_train", "n_drive", "n_components", "n_test",
                               "n_drives", "drive_steps", "patch_floor"),
                  non_negative=("motion_noise", "seed", "forward_ridge", "verify", "turns",
                                "familiar_novelty", "smooth"),
                  prefix="appearance_")
    if c.smooth > 0 and c.features != "pixel_pca":
        raise UsageError("appearance_smooth", f"blurs PixelPCA's images only; with "
                         f"--appearance-features {c.features} it would do nothing")
    if not (c.verify_margin >= 1.0 and math.isfinite(c.verify_margin)):
        raise UsageError("appearance_verify_margin", "must be >= 1 (a candidate must explain "
                         f"the image at least as well as psi*), got {c.verify_margin!r}")
    check_output_dir("appearance_out_dir", c.out_dir)


def _check_coverage_bench(c: CoverageBenchConfig) -> None:
    check_int_list("coverage_cities", c.cities, minimum=0)
    check_choices("coverage_cameras", c.cameras, CAMERAS)
    check_choice("coverage_features", c.features, STREET_FEATURES)
    check_numbers(c, positive=("image_size", "n_train", "n_drive", "n_components", "n_test",
                               "n_drives", "drive_steps"),
                  non_negative=("motion_noise", "seed"), prefix="coverage_")
    check_output_dir("coverage_out_dir", c.out_dir)


def _check_parallel_bench(c: ParallelBenchConfig) -> None:
    check_choice("parallel_mode", c.mode, [m for m in MODES if m != "route"])
    check_numbers(c, positive=("n", "image_size", "workers", "rounds"),
                  non_negative=("scene_seed", "seed"), prefix="parallel_")
    check_output_dir("parallel_out_dir", c.out_dir)


def _check_noise_bench(c: NoiseBenchConfig) -> None:
    check_int_list("noise_cities", c.cities, minimum=0)
    check_choices("noise_conditions", c.conditions, CONDITION_NAMES)
    check_choice("noise_lanes", c.lanes, ["route", "streets"])
    check_choice("noise_normalize", c.normalize, NORMALIZATIONS)
    check_numbers(c, positive=("n_train", "image_size", "n_components", "n_drive", "n_drives",
                               "drive_steps", "noise_folds"),
                  non_negative=("motion_noise", "seed"), prefix="noise_")
    check_output_dir("noise_out_dir", c.out_dir)


def _check_city60_bench(c: City60BenchConfig) -> None:
    check_int_list("city60_cities", c.cities, minimum=0)
    check_choice("city60_features", c.features, STREET_FEATURES)
    check_numbers(c, positive=("city_size", "image_size", "density", "n_components", "n_drive",
                               "n_drives", "drive_steps", "episodes", "districts",
                               "lane_heading"),
                  non_negative=("motion_noise", "max_episode_steps", "seed", "overlap",
                                "heading_check", "familiar_novelty", "hold_speed"),
                  prefix="city60_")
    if c.hold_speed > 1.0:  # the env's speed bound
        raise UsageError("city60_hold_speed", f"must be <= 1 m/s, got {c.hold_speed}")
    try:
        check_city_layout(c.city_size)
    except ValueError as err:
        raise UsageError("city60_city_size", str(err)) from None
    if c.n_drive < 200:  # the noise's correlation time needs 4 blocks of 50 steps
        raise UsageError("city60_n_drive", f"must be >= 200, got {c.n_drive}")
    if c.filter not in ("ekf", "particles"):
        raise UsageError("city60_filter", f"must be 'ekf' or 'particles', got {c.filter!r}")
    check_output_dir("city60_out_dir", c.out_dir)
    if c.localizer_dir:
        check_output_dir("city60_localizer_dir", c.localizer_dir)


def _check_robustness_bench(c: RobustnessConfig) -> None:
    check_int_list("robustness_cities", c.cities, minimum=0)
    check_choices("robustness_conditions", c.conditions,
                  [*SPECIAL, *(n for n in CONDITION_NAMES if n != "random")])
    check_choices("robustness_sources", c.sources, ROBUST_SOURCES)
    check_choices("robustness_agents", c.agents, ROBUST_AGENTS)
    check_choice("robustness_randomised_features", c.randomised_features, STREET_FEATURES)
    check_choice("robustness_daylight_features", c.daylight_features, STREET_FEATURES)
    check_choice("robustness_randomised_map", c.randomised_map, RANDOMISED_MAPS)
    check_choice("robustness_daylight_lanes", c.daylight_lanes, DAYLIGHT_LANES)
    check_numbers(c, positive=("episodes", "image_size", "n_train", "n_train_randomised",
                               "n_drive", "max_steps",
                               "kidnap_at", "workers"),
                  non_negative=("seed", "motion_noise", "offset_doubt", "particle_offset_doubt",
                                "slow_steps", "guard_patience", "guard_agree",
                                "guard_memory", "particle_guard_patience",
                                "particle_guard_agree", "particle_guard_memory",
                                "familiar_novelty", "particle_familiar_novelty"),
                  prefix="robustness_")
    try:
        check_ray_address(c.ray_address)
    except (TypeError, ValueError) as err:
        raise UsageError("robustness_ray_address", str(err)) from None
    for name in ("oracle_policy", "belief_policy"):
        if getattr(c, name):
            check_existing_file(f"robustness_{name}", getattr(c, name))
    check_output_dir("robustness_out_dir", c.out_dir)


CHECKS = {"env": _check_env_bench, "gse": _check_gse_bench, "filter": _check_filter_bench,
          "agents": _check_agents_bench, "global": _check_global_bench,
          "appearance": _check_appearance_bench, "coverage": _check_coverage_bench,
          "parallel": _check_parallel_bench, "noise": _check_noise_bench,
          "city60": _check_city60_bench, "robustness": _check_robustness_bench}


def _config(args: Args, name: str) -> object:
    """The settings field of benchmark ``name`` (``global`` is a keyword: the field is ``global_``)."""
    return getattr(args, "global_" if name == "global" else name)


def check(args: Args) -> None:
    """``--only`` names benchmarks, and their options are valid."""
    for name in check_choices("only", args.only, BENCHMARKS):
        CHECKS[name](_config(args, name))


def run(args: Args) -> None:
    """Run the chosen benchmarks one after the other, in the order of ``make bench``."""
    chosen = set(args.only.split(","))
    for name in BENCHMARKS:
        if name in chosen:
            print(f"[bench] {name}", flush=True)
            _, run_one = benchmark(name)
            run_one(dataclasses.replace(_config(args, name)))
