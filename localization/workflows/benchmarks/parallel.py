"""Benchmark of scale-out: dataset collection on one process, on local worker processes and on
Ray tasks, side by side (``appearance-nav bench --only parallel``; options
``--parallel-<option>``).

    appearance-nav bench --only parallel                       # 20000 random 64x64 images
    appearance-nav bench --only parallel --parallel-quick      # smoke run

What is measured
----------------
``appearance-nav collect``'s work (:func:`localization.workflows.collect.collect_arrays`)
for the same dataset three ways, in rounds ``serial, processes, ray`` (``rounds`` times, so
load from other processes hits all alike):

* serial: ``workers=1``, this process;
* processes: ``workers`` forkserver processes, timed from the pool's start (worker start,
  imports and env builds included: what a user waits for);
* ray: ``workers`` Ray tasks in flight on a local Ray instance (``ray.init(num_cpus=workers)``,
  started once before the rounds and timed apart: a cluster is already running). Skipped with
  a note when Ray is not installed.

Reported: the median wall time of each, the CPU seconds of the collection tasks (summed
over the workers; worker start-up not included) and the cores they used (task CPU / wall),
samples/s, speed-up = median over rounds of serial time / parallel time, and whether the
arrays of every run are identical to the serial ones. Target (PASS/MISS): speed-up >= 1.6
with 2 workers on 2 cores, for both.

On a shared machine the wall times measure the share of the CPU the benchmark gets: Linux
schedules fairly between sessions (autogroups), not processes, so while other sessions keep
the cores busy two workers get no more CPU than one process ("cores used" ~1 for both); the
load averages are reported beside the table.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib.util
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from localization.workflows.collect import CollectConfig, collect_arrays

__all__ = ["TARGET_SPEEDUP", "ParallelBenchConfig", "run_parallel_bench"]

TARGET_SPEEDUP = 1.6
METHODS = ("serial", "processes", "ray")


@dataclass
class ParallelBenchConfig:
    """Settings of the scale-out benchmark."""

    mode: str = field(default="random", metadata={
        "help": "collection mode (any but route, which is one task)"})
    n: int = field(default=20000, metadata={"help": "samples collected by each run"})
    image_size: int = field(default=64, metadata={"help": "side of the square camera image"})
    workers: int = field(default=2, metadata={"help": "worker processes / Ray tasks in flight"})
    rounds: int = field(default=3, metadata={"help": "rounds of serial, processes, ray"})
    scene_seed: int = field(default=0, metadata={"help": "the city"})
    seed: int = field(default=0, metadata={"help": "seed of the poses"})
    quick: bool = field(default=False, metadata={"help": "smoke run: 1200 samples, one round"})
    out_dir: str = field(default="results", metadata={
        "help": "where bench_parallel.json / bench_parallel.md go"})

    def resolved(self) -> ParallelBenchConfig:
        """The settings actually run (``quick`` shrinks them)."""
        if not self.quick:
            return self
        return dataclasses.replace(self, n=min(self.n, 1200), rounds=1)


def _digest(images: np.ndarray, poses: np.ndarray) -> str:
    """SHA-256 of the arrays (identical arrays, identical digests)."""
    return hashlib.sha256(images.tobytes() + poses.tobytes()).hexdigest()


def _timed(config: CollectConfig) -> tuple[float, float, str]:
    """Wall seconds, CPU seconds of the collection tasks (in whichever process they ran) and
    the digest of the arrays of one collection."""
    t0 = time.perf_counter()
    images, poses, info = collect_arrays(config, progress=False)
    return time.perf_counter() - t0, info["cpu_seconds"], _digest(images, poses)


def _start_ray(workers: int) -> tuple[float | None, bool]:
    """Start a local Ray instance with ``workers`` CPUs unless one runs: its start-up seconds
    (None: no Ray installed; 0: already running) and whether this call started it."""
    if importlib.util.find_spec("ray") is None:
        return None, False
    import ray

    if ray.is_initialized():
        return 0.0, False
    t0 = time.perf_counter()
    ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    return time.perf_counter() - t0, True


def _load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def markdown(rows: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    """The table of the rows."""
    a = meta["args"]
    ray_start = ("not installed" if meta["ray_start_seconds"] is None
                 else f"{meta['ray_start_seconds']:.1f} s, not counted")
    lines = [
        "# Scale-out: dataset collection",
        "",
        (f"`collect` of {a['n']} {a['mode']} {a['image_size']}x{a['image_size']} images, "
         f"{a['workers']} workers, median of {a['rounds']} round(s) of serial / processes / "
         f"ray; times include starting the worker processes (Ray's local instance start-up: "
         f"{ray_start}). {meta['cpu_count']} CPUs, load average at start {meta['loadavg']}, "
         f"at end {meta['loadavg_end']}."),
        "",
        ("| run | workers | wall (s) | task CPU (s) | cores used | samples/s | speed-up | "
         f"identical to serial | >= {TARGET_SPEEDUP}x |"),
        "|---|---:|---:|---:|---:|---:|---:|---|---|",
    ]
    for r in rows:
        if r["seconds"] is None:
            lines.append(f"| {r['method']} | {r['workers']} | - | - | - | - | - | - | "
                         f"skipped: {r['note']} |")
            continue
        target = "" if r["method"] == "serial" else \
            ("PASS" if r["speedup"] >= TARGET_SPEEDUP else "MISS")
        lines.append(f"| {r['method']} | {r['workers']} | {r['seconds']:.1f} | "
                     f"{r['cpu_seconds']:.1f} | {r['cpu_share']:.2f} | "
                     f"{r['samples_per_s']:.0f} | {r['speedup']:.2f} | "
                     f"{'yes' if r['identical'] else 'NO'} | {target} |")
    return "\n".join(lines) + "\n"


def run_parallel_bench(args: ParallelBenchConfig) -> list[dict[str, Any]]:
    """Run the benchmark; write ``bench_parallel.json`` / ``.md``; return the rows."""
    args = args.resolved()
    base = CollectConfig(mode=args.mode, n=args.n, seed=args.seed, scene_seed=args.scene_seed,
                         height=args.image_size, width=args.image_size)
    configs = {"serial": base, "processes": dataclasses.replace(base, workers=args.workers),
               "ray": dataclasses.replace(base, workers=args.workers, ray_address="auto")}
    meta: dict[str, Any] = {"args": dataclasses.asdict(args), "cpu_count": os.cpu_count(),
                            "loadavg": _load()}
    meta["ray_start_seconds"], started = _start_ray(args.workers)
    methods = [m for m in METHODS if m != "ray" or meta["ray_start_seconds"] is not None]
    times: dict[str, list[float]] = {m: [] for m in methods}
    cpu: dict[str, list[float]] = {m: [] for m in methods}
    digests: dict[str, set[str]] = {m: set() for m in methods}
    try:
        for k in range(args.rounds):
            for m in methods:
                seconds, cpu_seconds, digest = _timed(configs[m])
                times[m].append(seconds)
                cpu[m].append(cpu_seconds)
                digests[m].add(digest)
                print(f"round {k + 1}: {m:>9s} {seconds:6.1f} s  load {_load()}", flush=True)
    finally:
        if started:
            import ray

            ray.shutdown()
    meta["loadavg_end"] = _load()
    serial = np.array(times["serial"])
    rows = []
    for m in METHODS:
        workers = 1 if m == "serial" else args.workers
        if m not in methods:
            rows.append({"method": m, "workers": workers, "seconds": None,
                         "note": "Ray is not installed (the distributed extra)"})
            continue
        t = np.array(times[m])
        rows.append({"method": m, "workers": workers, "seconds": float(np.median(t)),
                     "times": [round(v, 3) for v in t],
                     "samples_per_s": args.n / float(np.median(t)),
                     "cpu_seconds": float(np.median(cpu[m])),
                     "cpu_share": float(np.median(np.array(cpu[m]) / t)),
                     "speedup": float(np.median(serial / t)),
                     "identical": digests[m] == digests["serial"] and len(digests[m]) == 1})
    table = markdown(rows, meta)
    print("\n" + table)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_parallel.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    (out / "bench_parallel.md").write_text(table)
    return rows
