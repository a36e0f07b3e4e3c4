"""The noise-model comparison: its summary and table on hand-made runs, its options."""

from __future__ import annotations

import pytest

from localization.workflows.benchmarks import noise_models
from localization.workflows.benchmarks.noise_models import NoiseBenchConfig, markdown, summarize
from localization.workflows.tracking import nees_band


def test_summary_pools_drives_against_the_band_of_their_number():
    runs = [{"rmse": 0.1, "nees_mean": 4.0, "accepted": 1.0},
            {"rmse": 0.3, "nees_mean": 12.0, "accepted": 0.5}]
    s = summarize(runs)
    assert s["nees_mean"] == pytest.approx(8.0)
    assert s["nees_band"] == pytest.approx(list(nees_band(2)))
    assert s["in_band"] is False  # 8.0 > the upper bound for 2 drives (7.2)
    assert s["rmse"] == pytest.approx((0.5 * (0.01 + 0.09)) ** 0.5)
    assert s["accepted"] == pytest.approx(0.75)
    table = markdown({"summary": {"31/default": {"global": s, "heteroscedastic": summarize(
        runs[:1])}}})
    assert "| 31/default |" in table and "8.00 (out)" in table and "4.00 |" in table


def test_command_line_options_reach_the_settings(monkeypatch):
    seen = {}
    monkeypatch.setattr(noise_models, "run_noise_bench", lambda args: seen.update(a=args))
    noise_models.main(["--cities", "21,22", "--n-drives", "2", "--motion-noise", "0.2"])
    assert seen["a"] == NoiseBenchConfig(cities="21,22", n_drives=2, motion_noise=0.2)
