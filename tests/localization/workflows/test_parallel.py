"""map_tasks and parallel collection: serial, local processes and Ray give the same results."""

from __future__ import annotations

import math
import socket
import sys
from collections.abc import Iterator

import numpy as np
import pytest

import envs
from localization.workflows import collect
from localization.workflows.collect import CollectConfig, collect_arrays, collect_tasks
from localization.workflows.parallel import check_ray_address, map_tasks


@pytest.fixture
def small_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Slices of 40 samples, so a 100-sample dataset is three tasks (40, 40, 20)."""
    monkeypatch.setattr(collect, "CHUNK", 40)


@pytest.fixture(scope="module")
def ray_session() -> Iterator[object]:
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=200 * 2**20,
             log_to_driver=False)
    yield ray
    ray.shutdown()


def _config(**kw: object) -> CollectConfig:
    return CollectConfig(**{"n": 100, "height": 16, "width": 16, "seed": 5, **kw})


def _whole(c: CollectConfig) -> tuple[np.ndarray, np.ndarray]:
    """One ``envs.collect_dataset`` call: what ``collect`` gave before it collected in slices."""
    import gymnasium as gym

    env = gym.make("AppearanceNav-v0", image_size=(c.height, c.width),
                   motion_noise=c.motion_noise, conditions=c.conditions)
    try:
        return envs.collect_dataset(env, c.n, c.mode, seed=c.seed, progress=False)
    finally:
        env.close()


# ----------------------------------------------------------------------------- map_tasks
@pytest.mark.parametrize("workers", [1, 2])
def test_map_tasks_keeps_the_task_order(workers: int) -> None:
    tasks = [-5, 3, -1, 8, -2, 0, 7]
    assert map_tasks(abs, tasks, workers=workers, progress=False) == [5, 3, 1, 8, 2, 0, 7]


@pytest.mark.parametrize("workers", [1, 2])
def test_map_tasks_raises_the_task_error(workers: int) -> None:
    with pytest.raises(ValueError, match="math domain error"):
        map_tasks(math.sqrt, [4.0, -1.0, 9.0], workers=workers, progress=False)


def _torch_conv_threads(seed: int) -> tuple[int, bytes]:
    """torch's thread count inside a task, and a convolution's output bytes."""
    import torch

    g = torch.Generator().manual_seed(seed)
    x, w = torch.randn(4, 16, 32, 32, generator=g), torch.randn(32, 16, 3, 3, generator=g)
    return torch.get_num_threads(), torch.nn.functional.conv2d(x, w).numpy().tobytes()


def test_serial_tasks_run_on_one_thread_like_the_workers() -> None:
    """Two threads sum a convolution in another order than one: a serial run on torch's
    default threads gave other closed-loop episodes than a parallel one (by 0.2 mm)."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        serial = map_tasks(_torch_conv_threads, [0, 1], workers=1, progress=False)
        assert torch.get_num_threads() == 2  # restored after the run
    finally:
        torch.set_num_threads(before)
    assert [threads for threads, _ in serial] == [1, 1]
    assert serial == map_tasks(_torch_conv_threads, [0, 1], workers=2, progress=False)


def _split_fit(seed: int) -> None:
    """A GSE fit whose neighbourhood graph falls in two (a module-level task for workers)."""
    from localization.gse.embedding import GrassmannStiefelEigenmaps
    from localization.synthetic import swiss_roll

    Z, _, _ = swiss_roll(300, seed=seed)
    GrassmannStiefelEigenmaps(2, n_neighbors=10).fit(np.vstack([Z, Z + 500.0]))


def test_a_worker_s_disconnected_graph_comes_back_with_its_labels() -> None:
    # the error crosses the process boundary (before, unpickling it broke the whole pool)
    from localization.gse.graph import DisconnectedGraphError

    with pytest.raises(DisconnectedGraphError, match="2 connected components") as info:
        map_tasks(_split_fit, [0, 1], workers=2, progress=False)
    assert np.bincount(info.value.labels).tolist() == [300, 300]


def test_map_tasks_on_ray_keeps_the_task_order(ray_session: object) -> None:
    tasks = list(range(-6, 6))
    assert map_tasks(abs, tasks, workers=2, ray_address="auto", progress=False) == \
        [abs(t) for t in tasks]
    with pytest.raises(ValueError, match="math domain error"):
        map_tasks(math.sqrt, [4.0, -1.0], workers=2, ray_address="auto", progress=False)


# ---------------------------------------------------------------------------- collection
def test_slices_do_not_depend_on_workers(small_chunks: None) -> None:
    tasks = collect_tasks(_config(workers=1))
    assert [(t.start, t.stop) for t in tasks] == [(0, 40), (40, 80), (80, 100)]
    assert [(t.start, t.stop) for t in collect_tasks(_config(workers=7))] == \
        [(t.start, t.stop) for t in tasks]
    assert [(t.start, t.stop) for t in collect_tasks(_config(mode="route"))] == [(0, 100)]


@pytest.mark.parametrize("mode", ["grid", "random"])
def test_serial_collection_is_unchanged_by_the_slices(mode: str, small_chunks: None) -> None:
    c = _config(mode=mode)
    images, poses, meta = collect_arrays(c, progress=False)
    whole_images, whole_poses = _whole(c)
    np.testing.assert_array_equal(images, whole_images)
    np.testing.assert_array_equal(poses, whole_poses)
    assert meta == {"dt": pytest.approx(0.1), "city_size": pytest.approx(20.0),
                    "cpu_seconds": pytest.approx(meta["cpu_seconds"])}
    assert meta["cpu_seconds"] > 0


@pytest.mark.parametrize("mode", ["lanes", "coverage"])
def test_drive_in_slices_match_the_whole_drive_in(mode: str, small_chunks: None) -> None:
    """The drive-in from a slice's start: the same images; the poses within rounding (the
    wheels' joint angles carry over from one drive-in to the next in the whole run)."""
    c = _config(mode=mode)
    images, poses, _ = collect_arrays(c, progress=False)
    whole_images, whole_poses = _whole(c)
    np.testing.assert_array_equal(images, whole_images)
    np.testing.assert_allclose(poses, whole_poses, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("mode", "extra"), [
    ("random", {}), ("lanes", {"motion_noise": 0.05}), ("random", {"conditions": "random"})])
def test_local_processes_give_the_serial_arrays(mode: str, extra: dict,
                                                small_chunks: None) -> None:
    serial = collect_arrays(_config(mode=mode, **extra), progress=False)
    parallel = collect_arrays(_config(mode=mode, workers=2, **extra), progress=False)
    np.testing.assert_array_equal(parallel[0], serial[0])
    np.testing.assert_array_equal(parallel[1], serial[1])


def test_ray_gives_the_serial_arrays(ray_session: object, small_chunks: None) -> None:
    for mode in ("grid", "lanes"):
        serial = collect_arrays(_config(mode=mode), progress=False)
        on_ray = collect_arrays(_config(mode=mode, workers=2, ray_address="auto"),
                                progress=False)
        np.testing.assert_array_equal(on_ray[0], serial[0])
        np.testing.assert_array_equal(on_ray[1], serial[1])


def test_a_slice_of_the_whole_dataset_is_checked() -> None:
    import gymnasium as gym

    env = gym.make("AppearanceNav-v0", image_size=(16, 16))
    try:
        with pytest.raises(ValueError, match="start, stop"):
            envs.collect_dataset(env, 10, "random", start=5, stop=11, progress=False)
        with pytest.raises(ValueError, match="start, stop"):
            envs.collect_dataset(env, 10, "random", start=5, stop=5, progress=False)
        with pytest.raises(ValueError, match="route"):
            envs.collect_dataset(env, 10, "route", start=2, progress=False)
    finally:
        env.close()


# ---------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize(("workers", "error"), [(0, ValueError), (-2, ValueError),
                                                 (1.5, TypeError), (True, TypeError)])
def test_bad_workers_are_refused(workers: object, error: type) -> None:
    with pytest.raises(error, match="workers"):
        map_tasks(abs, [1, 2], workers=workers, progress=False)


@pytest.mark.parametrize("address", ["nowhere", "ray://host", "http://host:10001", "host:port"])
def test_malformed_ray_addresses_are_refused(address: str) -> None:
    with pytest.raises(ValueError, match="ray_address"):
        check_ray_address(address)


def test_missing_ray_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(ImportError, match=r"ray_address.*distributed"):
        map_tasks(abs, [1, 2], ray_address="auto", progress=False)


def test_an_unreachable_ray_address_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    ray = pytest.importorskip("ray")
    monkeypatch.setattr(ray, "is_initialized", lambda: False)  # even beside a Ray session
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ConnectionError, match=rf"ray_address 'ray://127.0.0.1:{port}'"):
        map_tasks(abs, [1, 2], ray_address=f"ray://127.0.0.1:{port}", progress=False)


# ---------------------------------------------------------------------------- evaluation
def _eval(tmp_path: object, name: str, **kw: object) -> tuple[list[dict], dict]:
    import json
    from pathlib import Path

    from localization.workflows.navigation import EvalConfig, evaluate_agents

    out = Path(str(tmp_path)) / name
    rows = evaluate_agents(EvalConfig(agents="scripted", sources="oracle", episodes=3,
                                      image_size=16, max_episode_steps=300, out=str(out), **kw))
    return rows, json.loads((out / "agents.json").read_text())


def _without_wall_seconds(rows: list[dict]) -> str:
    """The rows but their timing, as JSON (NaN == NaN there)."""
    import json

    return json.dumps([{k: v for k, v in r.items() if k != "wall_seconds"} for r in rows])


def test_eval_sweep_on_processes_and_ray_equals_the_serial_one(tmp_path: object,
                                                               ray_session: object) -> None:
    rows, saved = _eval(tmp_path, "serial")
    assert [e["seed"] for e in saved["episodes"]["scripted/oracle"]] == \
        [2_000_000, 2_000_001, 2_000_002]
    assert any(e["success"] for e in saved["episodes"]["scripted/oracle"])
    for name, kw in (("processes", {"workers": 2}),
                     ("ray", {"workers": 2, "ray_address": "auto"})):
        other_rows, other = _eval(tmp_path, name, **kw)
        assert other["episodes"] == saved["episodes"], name
        assert _without_wall_seconds(other_rows) == _without_wall_seconds(rows), name
        assert other["args"] == {**saved["args"], "out": str(tmp_path) + "/" + name}


def test_eval_rerun_with_workers_is_refused(tmp_path: object) -> None:
    with pytest.raises(ValueError, match="rerun"):
        _eval(tmp_path, "x", workers=2, rerun=str(tmp_path) + "/e.rrd")


# ----------------------------------------------------------------------------- benchmark
def test_parallel_benchmark_reports_identical_arrays(tmp_path: object, small_chunks: None,
                                                     ray_session: object) -> None:
    import json
    from pathlib import Path

    from localization.workflows.benchmarks.parallel import ParallelBenchConfig, run_parallel_bench

    out = Path(str(tmp_path))
    rows = run_parallel_bench(ParallelBenchConfig(n=100, image_size=16, rounds=1,
                                                  out_dir=str(out)))
    assert [r["method"] for r in rows] == ["serial", "processes", "ray"]
    assert all(r["identical"] for r in rows)
    assert rows[0]["speedup"] == 1.0 and all(r["seconds"] > 0 < r["cpu_seconds"] for r in rows)
    saved = json.loads((out / "bench_parallel.json").read_text())
    assert saved["rows"] == json.loads(json.dumps(rows))
    assert "| processes | 2 |" in (out / "bench_parallel.md").read_text()
