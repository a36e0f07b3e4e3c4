"""The navigation metrics against hand-computed cases: SPL and the standard errors."""

from __future__ import annotations

import numpy as np
import pytest

from agents.evaluation import Episode, mean_and_se, metric_cells, spl, summarize


def _episode(success: bool, shortest: float, travelled: float, collisions: int = 0,
             steps: int = 100, rmse: float = 0.1, traffic: int = 0,
             tipped: bool = False) -> Episode:
    return Episode(seed=0, success=success, steps=steps, time=steps * 0.1, path_length=travelled,
                   shortest=shortest, collision_steps=collisions, final_distance=0.0,
                   belief_rmse=rmse, traffic_collision_steps=traffic, tipped_over=tipped)


def test_spl_hand_computed() -> None:
    # 10 m shortest, 12.5 m driven: 0.8; a failure scores 0 however short its path;
    # a path shorter than the reference (goal radius) scores 1: mean (0.8 + 0 + 1) / 3
    assert spl([True], [10.0], [12.5]) == pytest.approx(0.8)
    assert spl([False], [10.0], [10.0]) == 0.0
    assert spl([True, False, True], [10.0, 5.0, 4.0], [12.5, 5.0, 3.0]) == pytest.approx(0.6)
    assert spl([True], [0.0], [0.0]) == 1.0  # started at the goal
    assert _episode(True, 6.0, 8.0).spl == pytest.approx(0.75)


@pytest.mark.parametrize("args, match", [
    (([True, False], [1.0], [1.0, 2.0]), "1-D of one non-zero length"),
    (([], [], []), "1-D of one non-zero length"),
    (([True], [-1.0], [1.0]), "shortest must hold finite lengths"),
    (([True], [1.0], [np.nan]), "path_length must hold finite lengths"),
])
def test_spl_rejects_bad_input(args: tuple, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        spl(*args)


def test_mean_and_se() -> None:
    assert mean_and_se([1.0, 3.0]) == pytest.approx((2.0, 1.0))  # std 1.414 / sqrt 2
    assert mean_and_se([5.0]) == (5.0, 0.0)
    assert all(np.isnan(mean_and_se([])))


def test_summarize_reports_metrics_with_standard_errors() -> None:
    runs = [_episode(True, 10.0, 12.5, collisions=2, steps=100, rmse=0.3),
            _episode(True, 10.0, 10.0, steps=200, rmse=0.4),
            _episode(True, 4.0, 8.0, steps=300, rmse=0.0),
            _episode(False, 10.0, 3.0, collisions=4, steps=400, rmse=1.2, traffic=3, tipped=True)]
    s = summarize(runs)
    assert s["tipped_over_episodes"] == 0.25
    assert s["success_rate"] == 0.75
    assert s["success_rate_se"] == pytest.approx(np.sqrt(0.75 * 0.25 / 4))
    assert s["spl"] == pytest.approx((0.8 + 1.0 + 0.5 + 0.0) / 4)
    assert s["collisions_per_episode"] == 1.5
    assert s["collisions_per_episode_se"] == pytest.approx(np.std([2, 0, 0, 4], ddof=1) / 2)
    assert s["traffic_collisions_per_episode"] == 0.75
    assert s["time_to_goal"] == pytest.approx(20.0)  # successes only: 10, 20, 30 s
    assert s["belief_rmse"] == pytest.approx(np.sqrt((0.09 + 0.16 + 0.0 + 1.44) / 4))
    assert 0 < s["belief_rmse_se"] < s["belief_rmse"]
    assert metric_cells(s)[:2] == ["0.75 ± 0.22", "0.57 ± 0.22"]


def test_summarize_rejects_no_episodes() -> None:
    with pytest.raises(ValueError, match="no episodes"):
        summarize([])
