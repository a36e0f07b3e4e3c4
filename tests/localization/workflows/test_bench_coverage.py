"""The coverage benchmark: its scores on hand-made inputs, its options, a quick run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks import BENCHMARKS, benchmark
from localization.workflows.benchmarks.coverage import (
    SMALL_CNN_NEIGHBORS,
    CoverageBenchConfig,
    localizer_params,
    run_coverage_bench,
    single_image_errors,
    summarize_single,
)
from localization.workflows.benchmarks.street_features import localizer_features


def test_single_image_scores_use_both_thresholds_and_count_misses():
    truth = np.zeros((5, 3))
    pred = np.array([[0.2, 0, np.radians(1.0)],   # within all three
                     [0.2, 0, np.radians(3.0)],   # heading too far for (0.25 m, 2 deg)
                     [0.4, 0, 0.0],               # (0.5 m, 5 deg) and (5 m, 10 deg)
                     [4.0, 0, np.radians(9.0)],   # (5 m, 10 deg) only
                     [np.nan, np.nan, np.nan]])   # outside the domain: a miss
    s = summarize_single([single_image_errors(pred, truth)])
    assert s["within"] == pytest.approx([0.2, 0.6, 0.8])
    assert s["median_pos_err"] == pytest.approx(0.4)
    assert s["out_of_domain"] == pytest.approx(0.2)


@pytest.mark.parametrize("field, value, option", [
    ("cameras", "perspective,pinhole", "--coverage-cameras"),
    ("cities", "41,x", "--coverage-cities"),
    ("n_train", 0, "--coverage-n-train"),
    ("features", "sift", "--coverage-features"),
])
def test_bad_options_are_named(field, value, option):
    args = Args(only="coverage", coverage=CoverageBenchConfig(**{field: value}))
    with pytest.raises(UsageError, match=option):
        check(args)


def test_small_cnn_localizer_uses_the_camera_checkpoint_on_the_whole_image():
    params = localizer_params(CoverageBenchConfig(features="small_cnn"), "fisheye")
    assert params["features"] == "small_cnn" and params["rows"] == (0.0, 1.0)
    assert Path(params["features_params"]["weights"]).name == "small_cnn_fisheye_random.pt"
    assert params["regressor_params"] == {"n_neighbors": SMALL_CNN_NEIGHBORS}
    pixel = localizer_params(CoverageBenchConfig(features="pixel_pca", n_components=16), "fisheye")
    assert pixel == {"features_params": {"n_components": 16}}


def test_unknown_features_are_named():
    with pytest.raises(ValueError, match="features must be one of small_cnn, pixel_pca"):
        localizer_features("sift", "perspective", 64)


def test_registered_for_bench_only_coverage():
    config, run = benchmark("coverage")
    assert "coverage" in BENCHMARKS
    assert config is CoverageBenchConfig and run is run_coverage_bench


def test_quick_run_end_to_end(tmp_path: Path):
    run_coverage_bench(CoverageBenchConfig(quick=True, out_dir=str(tmp_path)))
    saved = json.loads((tmp_path / "bench_coverage.json").read_text())
    table = (tmp_path / "bench_coverage.md").read_text()
    s = saved["summary"]["perspective"]
    for method in ("GSE", "GSE refined", "KNR", "retrieval"):
        assert s["single"][method]["n_images"] == 40
        within = s["single"][method]["within"]
        assert within == sorted(within) and all(0.0 <= v <= 1.0 for v in within)
        assert f"| perspective | {method} |" in table
    loop = s["closed_loop"]["coverage"]
    assert loop["drives"] == 1 and math.isfinite(loop["rmse"]) and loop["rmse"] > 0
    assert "| perspective | coverage | 1 |" in table
