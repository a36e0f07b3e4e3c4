"""The 60 m city benchmark: its options, its registration, a quick run; the training size
that grows with the street area."""

from __future__ import annotations

import json
import math
from pathlib import Path

import gymnasium as gym
import pytest

import envs  # noqa: F401
from localization.cli._args import UsageError
from localization.cli.bench import Args, check
from localization.workflows.benchmarks import BENCHMARKS, benchmark
from localization.workflows.benchmarks.city60 import City60BenchConfig, run_city60_bench
from localization.workflows.tracking import street_train_size


@pytest.mark.parametrize("field, value, option", [
    ("cities", "51,x", "--city60-cities"),
    ("density", 0.0, "--city60-density"),
    ("city_size", 5.0, "--city60-city-size"),
    ("n_drive", 100, "--city60-n-drive"),
    ("max_episode_steps", -1, "--city60-max-episode-steps"),
    ("districts", 0, "--city60-districts"),
    ("features", "orb", "--city60-features"),
    ("overlap", -1.0, "--city60-overlap"),
    ("filter", "ukf", "--city60-filter"),
    ("heading_check", -0.1, "--city60-heading-check"),
    ("familiar_novelty", -1.0, "--city60-familiar-novelty"),
    ("lane_heading", 0.0, "--city60-lane-heading"),
    ("hold_speed", -0.1, "--city60-hold-speed"),
    ("hold_speed", 1.5, "--city60-hold-speed"),
])
def test_bad_options_are_named(field, value, option):
    args = Args(only="city60", city60=City60BenchConfig(**{field: value}))
    with pytest.raises(UsageError, match=option):
        check(args)


def test_registered_for_bench_only_city60():
    config, run = benchmark("city60")
    assert "city60" in BENCHMARKS
    assert config is City60BenchConfig and run is run_city60_bench
    assert City60BenchConfig().cities == "51,52"  # the held-out cities; 53 tunes


def test_training_size_grows_with_the_street_area():
    sizes = {}
    for size in (20.0, 60.0):
        env = gym.make("AppearanceNav-v0", city_size=size)
        sizes[size] = street_train_size(env, 24.0)
        env.close()
    assert sizes[20.0] == math.ceil(24.0 * 256)
    assert sizes[60.0] == math.ceil(24.0 * 2000)
    env = gym.make("AppearanceNav-v0")
    with pytest.raises(ValueError, match="density"):
        street_train_size(env, -1.0)
    env.close()


@pytest.mark.parametrize("belief", ["ekf", "particles"])
def test_quick_run_end_to_end(tmp_path: Path, belief: str):
    run_city60_bench(City60BenchConfig(quick=True, out_dir=str(tmp_path), filter=belief))
    saved = json.loads((tmp_path / "bench_city60.json").read_text())
    table = (tmp_path / "bench_city60.md").read_text()
    s = saved["summary"]["51"]
    assert s["n_train"] == math.ceil(1.0 * 2000)
    loop = s["closed_loop"]
    assert loop["drives"] == 1 and loop["rmse"] >= 0 and loop["rmse_dead_reckoning"] >= 0
    lo, hi = loop["nees_band"]
    assert 0 < lo < 3 < hi
    for source in ("belief", "oracle"):
        agents = s["agents"][source]
        assert agents["episodes"] == 1 and 0.0 <= agents["success_rate"] <= 1.0
        assert len(saved["records"]["51"]["agents"][source]) == 1
    assert saved["records"]["51"]["agents"]["belief"][0]["steps"] <= 40
    assert s["single_image"]["images"] == 20 and s["single_image"]["median"] >= 0
    assert "| 51 | 2000 | " in table and "<= 0.20" in table and "districts" in table
    assert "60 m" in saved["setup"] and f"{belief} belief" in saved["setup"]
    assert ("restarts from familiar images" in saved["setup"]) == (belief == "ekf")
    assert "looks around while lost" in saved["setup"]  # the tour pilot's Recovery, by default
    assert "keeps its course at 0.3 m/s while relocalizing" in saved["setup"]
    assert 0.0 < loop["distance"] < 40 * 0.1 * 1.0 + 1e-9  # 40 steps of 0.1 s, |v| <= 1 m/s


def test_a_failed_fit_is_reported_and_the_run_goes_on(tmp_path: Path, monkeypatch):
    from localization.workflows.benchmarks import city60

    def refuse(args, env):
        raise ValueError("the neighbourhood graph of 9 samples (k=3) has 2 connected components")

    monkeypatch.setattr(city60, "fit_city", refuse)
    result = run_city60_bench(City60BenchConfig(quick=True, out_dir=str(tmp_path)))
    assert result["summary"] == {}
    message = "the neighbourhood graph of 9 samples (k=3) has 2 connected components"
    assert result["fit_failures"] == [f"city 51: {message}"]
    saved = json.loads((tmp_path / "bench_city60.json").read_text())
    assert saved["fit_failures"] == result["fit_failures"]
    assert "Fit failed: city 51" in (tmp_path / "bench_city60.md").read_text()


def test_a_saved_localizer_is_reused_for_its_city_only(tmp_path: Path, monkeypatch):
    from localization.workflows.benchmarks import city60

    maps = tmp_path / "maps"
    first = run_city60_bench(City60BenchConfig(quick=True, out_dir=str(tmp_path / "a"),
                                               localizer_dir=str(maps)))
    assert (maps / "localizer_51.npz").is_file()
    full = City60BenchConfig(localizer_dir=str(maps))  # 64 px: not the quick run's 32 px maps
    with pytest.raises(ValueError, match="localizer_51.npz holds maps of .*not 64 px"):
        city60.fit_or_load(full, city60.make_env(full.resolved(), 51), 51)

    def refit(args, env):
        raise AssertionError("the saved localizer should have been loaded")

    monkeypatch.setattr(city60, "fit_city", refit)
    again = run_city60_bench(City60BenchConfig(quick=True, out_dir=str(tmp_path / "b"),
                                               localizer_dir=str(maps)))
    assert again["fit_failures"] == []
    for before, after in zip(first["records"]["51"]["drives"], again["records"]["51"]["drives"]):
        before.pop("ms_per_step"), after.pop("ms_per_step")  # a clock, not a result
        assert after == before  # the same maps, the same tour
    assert set(again["stage_seconds"][0]) >= {"city", "load", "tours"}
    # a file that holds another city's maps is reported, not used
    (maps / "localizer_51.npz").rename(maps / "localizer_52.npz")
    other = run_city60_bench(City60BenchConfig(quick=True, cities="52", localizer_dir=str(maps),
                                               out_dir=str(tmp_path / "c")))
    assert other["summary"] == {}
    assert other["fit_failures"][0].startswith(f"city 52: {maps / 'localizer_52.npz'}: ")
    assert "fitted on" in other["fit_failures"][0]


def test_tours_drive_with_the_configured_recovery(monkeypatch):
    """The setup label is not the tours: each tour gets its own Recovery with the env's w_max
    and ``hold_speed`` (0: none), or no recovery at all without ``recover``."""
    import dataclasses
    from types import SimpleNamespace

    from localization.workflows.benchmarks import city60

    seen: list = []
    monkeypatch.setattr(city60, "track_streets",
                        lambda *a, recover, **kw: seen.append(recover))
    monkeypatch.setattr(city60, "track_metrics", lambda run: {})
    env = SimpleNamespace(unwrapped=SimpleNamespace(W_MAX=0.8))
    args = City60BenchConfig(n_drives=2)
    city60.tours(args, env, None, 100)
    assert [(r.w_max, r.hold_speed) for r in seen] == [(0.8, 0.3)] * 2 and seen[0] is not seen[1]
    seen.clear()
    city60.tours(dataclasses.replace(args, hold_speed=0.0), env, None, 100)
    assert [r.hold_speed for r in seen] == [None, None]
    seen.clear()
    city60.tours(dataclasses.replace(args, recover=False), env, None, 100)
    assert seen == [False, False]


def test_the_belief_predicts_turns_with_the_robot_s_response_when_asked():
    """``turn_response`` (off by default) reaches the EKF's options; the particles get none."""
    import dataclasses

    from localization.workflows.benchmarks.city60 import _belief, _filter_label

    args = City60BenchConfig()
    assert "turn_response" not in _belief(args)["filter_options"]
    assert "measured rate" not in _filter_label(args)
    on = dataclasses.replace(args, turn_response=True)
    assert _belief(on)["filter_options"]["turn_response"] is True
    assert "measured rate" in _filter_label(on)
    assert _belief(dataclasses.replace(on, filter="particles")) == {"filter": "particles"}
