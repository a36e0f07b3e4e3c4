"""The paper's experiment end to end, small (:func:`localization.workflows.paper.run_paper`
with ``quick``, run as ``appearance-nav reproduce --quick`` in a fresh process), and its
settings."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from localization.workflows.paper import PaperConfig

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("paper")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1",  # the other xdist worker has the second core
           "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([sys.executable, "-m", "localization.cli", "reproduce", "--quick",
                           "--out", str(out), "--num-threads", "1"], check=False, cwd=ROOT,
                          capture_output=True, text=True, timeout=900, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_quick_settings_shrink_the_run() -> None:
    quick = PaperConfig(quick=True).resolved()
    assert (quick.n, quick.cv, quick.intrinsic_samples) == (500, 2, 400)
    assert quick.features == "pixel_pca,efficientnet,small_cnn"
    assert quick.imagenet_image_size == 96 and PaperConfig().imagenet_image_size == 128
    assert PaperConfig(quick=True, n=300).resolved().n == 300
    assert PaperConfig().resolved() == PaperConfig()


def test_quick_run_writes_the_tables_and_figures(quick_run: Path) -> None:
    tables = (quick_run / "tables.md").read_text()
    for heading in ("Table 1", "Table 2", "Random 3-DoF", "Figs. 2-3"):
        assert heading in tables
    for cam in ("perspective", "fisheye", "catadioptric"):
        assert cam in tables
    assert (quick_run / "reconstruction_tangent.png").stat().st_size > 10_000
    report = json.loads((quick_run / "results.json").read_text())
    assert set(report["table1"]) == {"perspective", "fisheye", "catadioptric"}
    assert set(report["table1_random"]) == {"perspective", "fisheye", "catadioptric"}
    # the global estimate on 5 subsamples of both data sets; Isomap (loop cut) on the
    # route's 5 and the random data's first
    for table, isomap in (("table1", 5), ("table1_random", 1)):
        assert all(len(t["global_seeds"]) == 5 and t["global"] == t["global_seeds"][0]
                   and len(t["isomap_seeds"]) == isomap
                   and all(r == max(1, round(v)) for r, v in zip(t["global_seeds"],
                                                                  t["global_values"]))
                   for t in report[table].values())
    assert "(1 in " in tables
    random_rows = [row for row in tables.splitlines() if "random 3-DoF poses |" in row]
    assert len(random_rows) == 3 and not any("(1 in " in row for row in random_rows)
    # the global estimate reads the route as a curve on every subsample (issue 15's Table 1
    # target), and the random 3-DoF views as more (quick run, 400 samples: slopes 1.31-1.40
    # on the route, 2.10-2.84 at random poses; it reads low on small samples)
    assert all(t["global_seeds"] == [1] * 5 for t in report["table1"].values())
    assert all(min(t["global_seeds"]) >= 2 for t in report["table1_random"].values())
    # 3 cameras x 2 data sets x 3 feature extractors x 3 methods, and GSE verified on the
    # route's 9 rows (the same model: its feature choice, a count of switched test images)
    assert len(report["table2"]) == 54 + 9
    route = [r for r in report["table2"] if r["dataset"] == "route"]
    gse = {(r["camera"], r["features"]): r["params"] for r in route if r["method"] == "gse"}
    verified = [r for r in route if r["method"] == "gse_verified"]
    assert len(verified) == 9 and all(
        r["params"]["n_features"] == gse[r["camera"], r["features"]]["n_features"]
        and r["params"].get("variant") == gse[r["camera"], r["features"]].get("variant")
        and isinstance(r["params"]["switched"], int) and r["rrmse"] > 0 for r in verified)
    assert "| GSE, verified |" in tables
    assert all(r["params"]["variant"] in ("plain", "whitened") for r in route
               if r["features"] != "small_cnn")
    assert all("variant" not in r["params"] for r in route if r["features"] == "small_cnn")


def test_quick_run_gse_ahead_of_knr_along_the_route(quick_run: Path) -> None:
    report = json.loads((quick_run / "results.json").read_text())
    rows = {(r["camera"], r["features"], r["method"]): r["rrmse"]
            for r in report["table2"] if r["dataset"] == "route"}
    for cam in ("perspective", "fisheye", "catadioptric"):
        for feat in ("pixel_pca", "efficientnet", "small_cnn"):
            assert rows[cam, feat, "gse"] < rows[cam, feat, "knr"], (cam, feat)
