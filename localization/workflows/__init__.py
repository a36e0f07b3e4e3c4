"""Workflows: the jobs built from the toolkit and the simulator (the one layer of
:mod:`localization` that imports :mod:`envs`).

- fitting a localizer for a city and closed-loop tracking (:mod:`.tracking`), its quality
  report (:mod:`.quality`), tracking runs
  over models and starts with their report (:mod:`.track_runs`);
- the demo pipeline (:mod:`.demo`), collecting a dataset to a file (:mod:`.collect`);
- training PPO navigators (:mod:`.training`) and evaluating navigators (:mod:`.navigation`);
- the paper's experiment: the methods (:mod:`.experiment`), the job (:mod:`.paper`), its
  figures and tables (:mod:`.paper_report`), camera masks (:mod:`.camera_masks`) and the
  feature-extractor factory (:mod:`.extractors`);
- training the SmallCNN on other cities (:mod:`.small_cnn_training`);
- benchmarks (:mod:`.benchmarks`);
- plots (:mod:`.plotting`).

Each job takes a settings dataclass (``DemoConfig``, ``TrackConfig``, ...) whose fields are
the options of its ``appearance-nav`` command.

Names load on first use (they import MuJoCo and matplotlib).
"""

from __future__ import annotations

from localization._lazy import lazy_names

_LAZY = {
    "TrackResult": "tracking",
    "fit_city_localizer": "tracking",
    "fit_city_noise": "tracking",
    "nees_band": "tracking",
    "track_metrics": "tracking",
    "track_route": "tracking",
    "track_streets": "tracking",
    "city_info": "tracking",
    "LocalizerQualityWarning": "quality",
    "kidnap_demo": "kidnap_demo",
    "CAMERAS": "sim",
    "LANE_SETS": "sim",
    "MODES": "sim",
    "plot_kidnap": "kidnap_demo",
    "quality_problems": "quality",
    "quality_report": "quality",
    "quality_table": "quality",
    "warn_quality": "quality",
    "GSE_GRID": "experiment",
    "MethodResult": "experiment",
    "evaluate_methods": "experiment",
    "fit_gse": "experiment",
    "position_errors": "experiment",
    "covariance_ellipse": "plotting",
    "plot_route": "plotting",
    "plot_track": "plotting",
    "CollectConfig": "collect",
    "collect_arrays": "collect",
    "collect_out_path": "collect",
    "map_tasks": "parallel",
    "collect_to_file": "collect",
    "DemoConfig": "demo",
    "demo_table": "demo",
    "run_demo": "demo",
    "TrackConfig": "track_runs",
    "summarize_runs": "track_runs",
    "track_markdown": "track_runs",
    "run_tracking": "track_runs",
    "TrainConfig": "training",
    "VEC_ENVS": "training",
    "make_vec_env": "training",
    "train_agent": "training",
    "AGENTS": "navigation",
    "AgentEnvSettings": "agent_env",
    "EvalConfig": "navigation",
    "agents_table": "navigation",
    "evaluate_agents": "navigation",
    "FEATURE_DIMS": "paper",
    "PaperConfig": "paper",
    "run_paper": "paper",
    "FEATURE_NAMES": "paper_report",
    "PAPER_TABLE1": "paper_report",
    "PAPER_TABLE2": "paper_report",
    "figures": "paper_report",
    "jsonable": "paper_report",
    "tables_markdown": "paper_report",
    "elevation_map": "camera_masks",
    "ground_mask": "camera_masks",
    "EXTRACTORS": "extractors",
    "make_extractor": "extractors",
    "SmallCNNTrainConfig": "small_cnn_training",
    "train_small_cnn_job": "small_cnn_training",
    "BENCHMARKS": "benchmarks",
    "benchmark": "benchmarks",
}
__all__ = [
    "AGENTS",
    "BENCHMARKS",
    "CAMERAS",
    "EXTRACTORS",
    "FEATURE_DIMS",
    "FEATURE_NAMES",
    "GSE_GRID",
    "LANE_SETS",
    "MODES",
    "PAPER_TABLE1",
    "PAPER_TABLE2",
    "VEC_ENVS",
    "AgentEnvSettings",
    "CollectConfig",
    "DemoConfig",
    "EvalConfig",
    "LocalizerQualityWarning",
    "MethodResult",
    "PaperConfig",
    "SmallCNNTrainConfig",
    "TrackConfig",
    "TrackResult",
    "TrainConfig",
    "agents_table",
    "benchmark",
    "city_info",
    "collect_arrays",
    "collect_out_path",
    "collect_to_file",
    "covariance_ellipse",
    "demo_table",
    "elevation_map",
    "evaluate_agents",
    "evaluate_methods",
    "figures",
    "fit_city_localizer",
    "fit_city_noise",
    "fit_gse",
    "ground_mask",
    "jsonable",
    "kidnap_demo",
    "make_extractor",
    "make_vec_env",
    "map_tasks",
    "nees_band",
    "plot_kidnap",
    "plot_route",
    "plot_track",
    "position_errors",
    "quality_problems",
    "quality_report",
    "quality_table",
    "run_demo",
    "run_paper",
    "run_tracking",
    "summarize_runs",
    "tables_markdown",
    "track_markdown",
    "track_metrics",
    "track_route",
    "track_streets",
    "train_agent",
    "train_small_cnn_job",
    "warn_quality",
]

__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals())
