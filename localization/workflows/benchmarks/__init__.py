"""Benchmarks (``appearance-nav bench``): speed and accuracy targets measured side by side
in one run, each writing JSON and a markdown table.

- :mod:`.env`: env steps/s against a raw MuJoCo step+render loop;
- :mod:`.gse`: GSE fit time, memory, query latency and accuracy against KNR and retrieval;
- :mod:`.filter`: the belief wrapper's per-step cost and closed-loop tracking accuracy;
- :mod:`.agents`: PPO on the belief against PPO on the true pose;
- :mod:`.global_loc`: kidnapping, global start, the look-alike city, nominal tracking and
  cost of every pose filter side by side;
- :mod:`.appearance`: single-image and closed-loop localization under every conditions
  preset (lighting, weather, camera effects, moving things), for a localizer trained on the
  default look and one trained on randomised conditions;
- :mod:`.coverage`: single-image and closed-loop localization anywhere on the street surface
  at any heading (coverage training, off-lane drives) against KNR and retrieval;
- :mod:`.parallel`: dataset collection on one process, on local worker processes and on Ray
  tasks, side by side;
- :mod:`.noise_models`: global against heteroscedastic measurement noise R;
- :mod:`.city60`: closed-loop tracking and the scripted agent on 60 m cities (nine times
  the default area);
- :mod:`.robustness`: the agents on every pose source, nominal, kidnapped, under each
  appearance preset and among moving things, with the navigation field's metrics.

:data:`BENCHMARKS` maps each name to its module, settings class and run function; modules
load on first use.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["BENCHMARKS", "benchmark"]

#: name -> (module, settings dataclass, run function), in the order ``make bench`` runs them
BENCHMARKS: dict[str, tuple[str, str, str]] = {
    "env": ("env", "EnvBenchConfig", "run_env_bench"),
    "gse": ("gse", "GSEBenchConfig", "run_gse_bench"),
    "filter": ("filter", "FilterBenchConfig", "run_filter_bench"),
    "agents": ("agents", "AgentsBenchConfig", "run_agents_bench"),
    "global": ("global_loc", "GlobalBenchConfig", "run_global_bench"),
    "appearance": ("appearance", "AppearanceBenchConfig", "run_appearance_bench"),
    "coverage": ("coverage", "CoverageBenchConfig", "run_coverage_bench"),
    "parallel": ("parallel", "ParallelBenchConfig", "run_parallel_bench"),
    "noise": ("noise_models", "NoiseBenchConfig", "run_noise_bench"),
    "city60": ("city60", "City60BenchConfig", "run_city60_bench"),
    "robustness": ("robustness", "RobustnessConfig", "run_robustness_bench"),
}


def benchmark(name: str) -> tuple[type, Callable[[Any], Any]]:
    """The settings dataclass and the run function of benchmark ``name``."""
    if name not in BENCHMARKS:
        raise ValueError(f"unknown benchmark {name!r}; choose from {list(BENCHMARKS)}")
    module, config, run = BENCHMARKS[name]
    mod = importlib.import_module(f"{__name__}.{module}")
    return getattr(mod, config), getattr(mod, run)
