"""The noise-model comparison: its summary and table on hand-made runs, its options."""

from __future__ import annotations

import pytest

from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks import BENCHMARKS, benchmark, noise_models
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


@pytest.mark.parametrize("field, value, option", [
    ("cities", "31,x", "--noise-cities"),
    ("conditions", "default,dawn", "--noise-conditions"),
    ("lanes", "free", "--noise-lanes"),
    ("n_drives", 0, "--noise-n-drives"),
])
def test_bad_options_are_named(field, value, option):
    args = Args(only="noise", noise=NoiseBenchConfig(**{field: value}))
    with pytest.raises(UsageError, match=option):
        check(args)


def test_registered_for_bench_only_noise():
    assert "noise" in BENCHMARKS
    config, run = benchmark("noise")
    assert config is NoiseBenchConfig and run is noise_models.run_noise_bench


def test_figure_of_hand_made_runs(tmp_path):
    from localization.workflows.benchmarks.noise_models import FILTERS, plot_nees

    runs = [{"rmse": 0.1, "nees_mean": 4.0, "accepted": 1.0},
            {"rmse": 0.3, "nees_mean": 12.0, "accepted": 0.5}]
    result = {"summary": {key: {n: summarize(runs) for n in FILTERS}
                          for key in ("31/default", "31/fog")}}
    path = plot_nees(result, tmp_path / "nees.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_target_counts_of_hand_made_runs():
    """Groups by the mean of their drives (band [1.10, 5.83] for 4), drives one by one
    (band [0.22, 9.35]): a group out with the global R because one drive of four is at 15."""
    from localization.workflows.benchmarks.noise_models import markdown, target_counts

    def group(nees):
        return [{"rmse": 0.1, "nees_mean": v, "accepted": 1.0} for v in nees]

    runs = {"31/default": {"global": group([3, 3, 3, 15]), "bias": group([3, 3, 3, 8]),
                           "heteroscedastic": group([3, 3, 3, 15]),
                           "adaptive": group([3, 3, 3, 10])},
            "31/fog": {n: group([2, 2, 2, 2]) for n in ("global", "bias", "heteroscedastic",
                                                         "adaptive")}}
    result = {"runs": runs, "summary": {g: {n: summarize(r) for n, r in v.items()}
                                        for g, v in runs.items()}}
    c = target_counts(result)
    assert c["global"] == {"groups": 2, "groups_in_band": 1, "global_out_groups": 1,
                           "global_out_groups_inside": 0, "drives": 8, "drives_in_band": 7,
                           "global_out_drives": 1, "global_out_drives_inside": 0}
    assert c["bias"]["global_out_groups_inside"] == 1 and c["bias"]["drives_in_band"] == 8
    assert c["adaptive"]["groups_in_band"] == 2  # (3 + 3 + 3 + 10) / 4 = 4.75: in the band
    assert c["adaptive"]["global_out_drives_inside"] == 0  # 10 > 9.35
    assert "| bias | 2 / 2 | 1 / 1 | 8 / 8 | 1 / 1 |" in markdown(result)
