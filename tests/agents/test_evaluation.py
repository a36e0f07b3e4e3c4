"""The navigation metrics against hand-computed cases: SPL and the standard errors."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers AppearanceNav-v0)
from agents.evaluation import Episode, mean_and_se, metric_cells, run_episode, spl, summarize


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


class _StatusBelief(gym.Wrapper):
    """A stand-in belief: its mean is the true position shifted by ``offsets[t]`` m along x,
    its status ``statuses[t]`` at step t."""

    def __init__(self, env: gym.Env, offsets: list[float], statuses: list[str]) -> None:
        super().__init__(env)
        self.offsets, self.statuses, self.t = offsets, statuses, 0

    def reset(self, **kwargs):
        _, info = self.env.reset(**kwargs)
        self.t = 0
        return {"pose_mean": info["pose"].copy()}, info

    def step(self, action):
        _, reward, terminated, truncated, info = self.env.step(action)
        mean = info["pose"] + np.array([self.offsets[self.t], 0.0, 0.0])
        info = {**info, "belief_status": self.statuses[self.t]}
        self.t += 1
        return {"pose_mean": mean}, reward, terminated, truncated, info


class _Still:
    def reset(self) -> None:
        pass

    def act(self, obs):
        return np.zeros(2, dtype=np.float32)


def test_misled_steps_count_tracking_claims_more_than_a_metre_off() -> None:
    # misleading: step 1 (tracking, 1.5 m) and 4 (tracking, 3 m); not: 0.5 m off while
    # tracking, 2 m off while lost or doubtful, just within 1 m while tracking
    offsets = [0.5, 1.5, 2.0, 2.0, 3.0, 0.99]
    statuses = ["tracking", "tracking", "lost", "doubtful", "tracking", "tracking"]
    env = _StatusBelief(gym.make("AppearanceNav-v0", image_size=(16, 16)), offsets, statuses)
    episode = run_episode(env, _Still(), seed=0, max_steps=6)
    env.close()
    assert episode.misled_steps == 2
    plain = gym.make("AppearanceNav-v0", image_size=(16, 16))
    no_status = run_episode(plain, _Still(), seed=0, max_steps=2)
    plain.close()
    assert no_status.misled_steps is None  # the env alone names no status


def test_summarize_misled_steps_over_the_episodes_that_measured_them() -> None:
    runs = [dataclasses.replace(_episode(True, 1.0, 1.0), misled_steps=m) for m in (0, 4, None)]
    s = summarize(runs)
    assert s["misled_steps_per_episode"] == 2.0 and s["misled_episodes"] == 0.5
    assert metric_cells(s)[-1] == "2.00 ± 2.00"
    none = summarize([_episode(True, 1.0, 1.0)])
    assert np.isnan(none["misled_steps_per_episode"]) and metric_cells(none)[-1] == "n/a"
    old = {k: v for k, v in s.items() if not k.startswith("misled")}  # a summary from before
    assert metric_cells(old)[-1] == "n/a"
