"""The global-localization benchmark: its scores on hand-made runs, its options, a quick run."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from envs.lookalike import generate_lookalike_city
from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks import BENCHMARKS, benchmark
from localization.workflows.benchmarks.global_loc import (
    GlobalBenchConfig,
    admitted,
    nees,
    run_global_bench,
    twin_scores,
    wrong_twin_run,
)


def test_admitted_counts_lost_steps_the_belief_owns_up_to():
    poses = np.zeros((4, 3))
    means = np.array([[0.2, 0, 0], [3.0, 0, 0], [3.0, 0, 0], [3.0, 0, 0]])
    tight, wide = np.diag([0.01, 0.01, 0.01]), np.diag([4.0, 4.0, 0.1])
    covs = np.array([tight, tight, wide, tight])  # step 2: 3 m inside the 3-sigma (6 m) ellipse
    statuses = ["initial", "tracking", "tracking", "lost"]
    assert admitted(means, covs, statuses, poses, 0) == (3, 2)
    assert admitted(means, covs, statuses, poses, 3) == (1, 1)


def test_wrong_twin_run_is_the_longest_stretch_on_a_twin():
    city = generate_lookalike_city(0)
    truth = np.array([-3.0, -9.0, 0.0])
    poses = np.tile(truth, (30, 1))
    means = poses.copy()
    means[5:27, 0] += city.period  # 22 steps on the twin one block east
    means[27:, 0] += 2.5  # lost, but not on a twin
    assert wrong_twin_run(means, poses, city, 0) == 22
    assert wrong_twin_run(means, poses, city, 10) == 17


def test_a_wrong_twin_counts_as_committed_only_while_the_status_claims_to_know():
    city = generate_lookalike_city(0)
    poses = np.tile([-3.0, -9.0, 0.0], (30, 1))
    means = poses.copy()
    means[5:27, 0] += city.period  # 22 steps on the twin one block east
    statuses = ["tracking"] * 30
    statuses[8:12] = ["ambiguous"] * 4  # owns up to it for 4 steps: runs of 3 and 15
    assert wrong_twin_run(means, poses, city, 0, statuses) == 15
    assert wrong_twin_run(means, poses, city, 0, ["ambiguous"] * 30) == 0
    assert wrong_twin_run(means, poses, city, 0) == 22  # the report alone


def test_twin_scores_count_frames_that_keep_the_truth_as_a_hypothesis():
    city = generate_lookalike_city(0)
    poses = np.tile([-3.0, -9.0, 0.0], (10, 1))
    means = poses.copy()
    means[2:8, 0] += city.period
    hyps = [{"weights": np.array([0.6, 0.4]), "means": np.array([m, p])}
            for m, p in zip(means, poses)]
    for t in (2, 3):  # the true twin dropped
        hyps[t] = {"weights": np.ones(1), "means": means[t][None]}
    drive = SimpleNamespace(kidnap=1, poses=poses)
    scores = twin_scores(means, ["ambiguous"] * 10, hyps, drive, city)
    assert scores == {"wrong_twin_run": 0, "twin_report_run": 6, "twin_frames": 6,
                      "twin_kept": 4}


def test_nees_wraps_the_heading():
    poses = np.array([[0.0, 0.0, np.pi - 0.05]])
    means = np.array([[0.0, 0.0, -np.pi + 0.05]])
    assert nees(means, np.eye(3)[None] * 0.01, poses)[0] == pytest.approx(0.01 / 0.01)


@pytest.mark.parametrize("field, value, option", [
    ("filters", "ekf,kalman", "--global-filters"),
    ("cities", "1,x", "--global-cities"),
    ("n_kidnaps", 0, "--global-n-kidnaps"),
    ("motion_noise", -1.0, "--global-motion-noise"),
])
def test_bad_options_are_named(field, value, option):
    args = Args(only="global", global_=GlobalBenchConfig(**{field: value}))
    with pytest.raises(UsageError, match=option):
        check(args)


def test_registered_for_bench_only_global():
    assert "global" in BENCHMARKS
    config, run = benchmark("global")
    assert config is GlobalBenchConfig and run is run_global_bench


def test_quick_run_end_to_end(tmp_path: Path):
    result = run_global_bench(GlobalBenchConfig(quick=True, out_dir=str(tmp_path)))
    saved = json.loads((tmp_path / "bench_global.json").read_text())
    table = (tmp_path / "bench_global.md").read_text()
    assert saved["filters"] == ["ekf", "ekf_detect", "particles"] == result["filters"]
    for name in saved["filters"]:
        s = saved["summary"][name]
        assert set(s) == {"kidnap", "nominal", "lookalike", "global", "agents"}
        assert s["agents"]["episodes"] == 1 and 0.0 <= s["agents"]["success_rate"] <= 1.0
        assert s["kidnap"]["n"] == 2 and s["lookalike"]["n"] == 1
        assert 0.0 <= s["kidnap"]["recovered_within_30"] <= 1.0
        assert 0.0 <= s["lookalike"]["wrong_twin_runs"] <= s["lookalike"]["twin_report_runs"] <= 1
        for key in ("rmse", "nees_mean", "ms_per_step"):
            assert math.isfinite(s["nominal"][key]) and s["nominal"][key] > 0, key
        assert s["kidnap"]["lost_steps"] > 0  # a kidnap of >= 5 m does throw every belief off
        assert 0.0 <= s["kidnap"]["admitted_while_lost"] <= 1.0
        assert name in table
    assert saved["summary"]["ekf"]["global"] is None  # no global start for the EKF
    assert saved["summary"]["particles"]["global"]["n"] == 1
    assert "look-alike city 24" in table
    assert "| measure | target | ekf | ekf_detect | particles |" in table
    assert "agents: scripted agent, one kidnap per episode" in table
    assert len(saved["agent_runs"]["particles"]) == 1
