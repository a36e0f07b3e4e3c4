"""Benchmark of GSERegressor: fit time / memory vs n, query latency, accuracy vs KNR and
retrieval (``appearance-nav bench --only gse``; its options are ``--gse-<option>``).

    appearance-nav bench --only gse              # full run: n = 1000, 2500, 5000, 10000 (m = 64)
    appearance-nav bench --only gse --gse-quick  # smoke run: n <= 1000
    appearance-nav bench --only gse --gse-scale-ns 10000,20000,40000,100000  # + the 100k row

The scalable-path rows (10k-100k) and the partial_fit run (1000 into 50000) are described
in :mod:`localization.workflows.benchmarks.gse_scale`.

What is measured
----------------
* Scaling (one fresh subprocess per n, so numbers do not leak between sizes): data
  ``regression_manifold(n, dim_theta=3, m)`` (x, y in [0,1]^2, periodic yaw), wall-clock
  ``GSERegressor(periodic=(2,)).fit`` time (after an untimed warm-up fit on 150 points,
  so lazy imports are not counted; it also masks the memory of fits with n <= 150), and
  peak memory of the fit as the growth of the process's peak resident set size,
  ``ru_maxrss`` after fit minus before fit (Linux, KiB -> MiB). It includes BLAS/LAPACK
  workspace and freed temporaries, unlike tracemalloc (which only sees allocations made
  through Python / numpy and slows the fit); ``--tracemalloc`` adds a second, traced fit
  and reports its numpy-level peak too.
* Latency at each n: ``predict`` (w -> theta) and ``predict_features`` (theta -> w) for
  one point (median of ``latency_repeats`` calls after a warm-up) and for a batch of
  ``batch_size`` held-out points (median of 3). Single queries are timed twice: with the
  worker's BLAS/OpenMP threads (``--threads``) and inside ``threadpool_limits(1)``: a
  one-row query is a GEMV that multi-threaded OpenBLAS splits for large n, and on a
  loaded machine the thread hand-off costs ~10 ms (seen at n = 10000 on a shared
  2-core box).
* Growth exponent: least-squares slope of log(fit time) vs log(n).
* Accuracy (in this process): train ``accuracy_n_train`` / test ``accuracy_n_test`` samples
  (70/30 of 2500 as in the seed paper) of ``regression_manifold`` with dim_theta = 2 and 3
  (same map, different sample seeds). psi* (w -> theta): position RRMSE over columns
  (x, y) (``localization.metrics.rrmse``) and heading RMSE (wrapped, rad). Phi*
  (theta -> w): RRMSE over all m feature columns against the true Phi. Baselines: KNR
  (``KernelRegressor``, one LOO bandwidth) and retrieval (``RetrievalRegressor``, k = 1 and
  k by 5-fold CV); for Phi their input is the pose with the yaw lifted to (cos, sin).
Targets (PASS/MISS): fit(n=2500) <= 20 s, fit(n=10000) <= 60 s, growth exponent <= 2
(well below cubic), one ``predict`` / ``predict_features`` query <= 1 ms at n = latency_n.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from localization.workflows.benchmarks.gse_accuracy import run_accuracy
from localization.workflows.benchmarks.gse_scale import (
    fmt_value,
    incremental_markdown,
    incremental_worker,
    scalable_markdown,
    scalable_summary,
    scalable_worker,
    scale_targets,
)
from localization.workflows.benchmarks.provenance import ROOT, provenance

__all__ = ["GSEBenchConfig", "run_gse_bench"]



@dataclass
class GSEBenchConfig:
    """Settings of the GSE benchmark."""

    ns: str = field(default="1000,2500,5000,10000",
                    metadata={"help": "comma-separated training sizes n for the scaling runs"})
    m: int = field(default=64, metadata={"help": "feature dimension m of the synthetic manifold"})
    seed: int = field(default=0, metadata={"help": "sample seed (test sets use seed+1)"})
    map_seed: int = field(default=1234, metadata={"help": "seed of the synthetic feature map Phi"})
    n_neighbors: int = field(default=20, metadata={"help": "GSERegressor n_neighbors"})
    batch_size: int = field(default=1000, metadata={"help": "batch size of the latency runs"})
    latency_repeats: int = field(default=100, metadata={"help": "single-query calls timed"})
    latency_n: int = field(default=2500, metadata={"help": "n at which the 1 ms query target "
                                                   "is judged (largest n run if absent)"})
    accuracy_n_train: int = field(default=1750, metadata={"help": "training size, accuracy runs"})
    accuracy_n_test: int = field(default=750, metadata={"help": "test size, accuracy runs"})
    accuracy_dims: str = field(default="2,3", metadata={"help": "dim_theta values compared"})
    skip_accuracy: bool = field(default=False, metadata={"help": "only run the scaling part"})
    skip_scaling: bool = field(default=False, metadata={"help": "only run the accuracy part"})
    tracemalloc: bool = field(default=False, metadata={"help": "also report the tracemalloc "
                                                       "peak of a second, traced fit"})
    threads: int = field(default=1, metadata={"help": "BLAS/OpenMP threads in the workers "
                                              "(0 = inherit the environment); 1 by default: "
                                              "on a shared box threaded BLAS on small "
                                              "matrices spins (n=250 fit 0.2 s vs 1-6 s)"})
    timeout: float = field(default=900.0, metadata={"help": "seconds allowed per scaling worker"})
    quick: bool = field(default=False, metadata={"help": "smoke run: n = 250,500,1000, "
                                                 "smaller accuracy sets, fewer repeats"})
    out: str = field(default="", metadata={"help": "output prefix (default results/bench_gse, "
                                           "results/bench_gse_quick with --quick)"})
    scale_ns: str = field(default="10000,20000,40000", metadata={
        "help": "sizes n of the scalable-path rows (algorithm='approximate'); add 100000 for "
                "issue 13's 100k targets (~2-5 min more)"})
    compare_n: int = field(default=10000, metadata={
        "help": "n at which the exact path is fitted beside the scalable one"})
    incremental_n: int = field(default=50000, metadata={"help": "base model size of the "
                                                        "partial_fit run"})
    incremental_new: int = field(default=1000, metadata={"help": "samples added by partial_fit"})
    skip_scalable: bool = field(default=False, metadata={"help": "skip the scalable-path rows"})
    skip_incremental: bool = field(default=False, metadata={"help": "skip the partial_fit run"})
    worker_kind: str = field(default="", metadata={"help": "internal: '', 'scalable' or "
                                                   "'incremental' worker"})
    worker_n: int = field(default=0, metadata={"help": "internal: run one scaling worker"})
    worker_out: str = field(default="", metadata={"help": "internal: worker JSON output path"})

    def resolved(self) -> GSEBenchConfig:
        """The settings actually run: ``quick`` shrinks the options left at their defaults;
        an empty ``out`` becomes ``results/bench_gse`` (``results/bench_gse_quick``)."""
        args = dataclasses.replace(self)
        if args.quick:
            if args.ns == GSEBenchConfig.ns:
                args.ns = "250,500,1000"
            if args.accuracy_n_train == GSEBenchConfig.accuracy_n_train:
                args.accuracy_n_train, args.accuracy_n_test = 700, 300
            if args.latency_repeats == GSEBenchConfig.latency_repeats:
                args.latency_repeats = 20
            if args.latency_n == GSEBenchConfig.latency_n:
                args.latency_n = 1000
            if args.scale_ns == GSEBenchConfig.scale_ns:
                args.scale_ns = "2000,4000"
                args.compare_n = 2000 if args.compare_n == GSEBenchConfig.compare_n \
                    else args.compare_n
            if args.incremental_n == GSEBenchConfig.incremental_n:
                args.incremental_n, args.incremental_new = 3000, 100
        if not args.out:
            args.out = "results/bench_gse_quick" if args.quick else "results/bench_gse"
        return args


# ---------------------------------------------------------------- scaling worker
def _median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def run_worker(args: GSEBenchConfig) -> dict[str, Any]:
    """Fit GSE at n = args.worker_n in this (fresh) process and time its queries."""
    from localization.gse.regressor import GSERegressor
    from localization.synthetic import regression_manifold

    n = args.worker_n
    W, T, _ = regression_manifold(n, dim_theta=3, m=args.m, seed=args.seed, map_seed=args.map_seed)
    Wt, Tt, _ = regression_manifold(args.batch_size, dim_theta=3, m=args.m, seed=args.seed + 1,
                                    map_seed=args.map_seed)
    # untimed warm-up fit: lazy imports and first-call set-up (~0.5-1 s) are not fit cost
    Ww, Tw, _ = regression_manifold(150, dim_theta=3, m=args.m, seed=args.seed + 2,
                                    map_seed=args.map_seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        GSERegressor(periodic=(2,), n_neighbors=args.n_neighbors).fit(Ww, Tw)
    model = GSERegressor(periodic=(2,), n_neighbors=args.n_neighbors,
                         random_state=args.seed)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        model.fit(W, T)
        fit_s = time.perf_counter() - t0
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    res: dict[str, Any] = {
        "n": n, "fit_s": fit_s, "peak_rss_delta_mib": (rss1 - rss0) / 1024.0,
        "peak_rss_mib": rss1 / 1024.0, "fit_warnings": sorted({str(w.message)[:120]
                                                               for w in caught}),
    }
    if args.tracemalloc:
        import tracemalloc

        tracemalloc.start()
        GSERegressor(periodic=(2,), n_neighbors=args.n_neighbors,
                     random_state=args.seed).fit(W, T)
        res["tracemalloc_peak_mib"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    w1, t1 = Wt[:1], Tt[:1]
    model.predict(w1), model.predict_features(t1)  # warm-up
    r = args.latency_repeats
    res["predict_1_ms"] = 1e3 * _median_time(lambda: model.predict(w1), r)
    res["predict_features_1_ms"] = 1e3 * _median_time(lambda: model.predict_features(t1), r)
    res["predict_batch_ms"] = 1e3 * _median_time(lambda: model.predict(Wt), 3)
    res["predict_features_batch_ms"] = 1e3 * _median_time(lambda: model.predict_features(Tt), 3)
    res["batch_size"] = len(Wt)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):  # one query is a GEMV: BLAS threads only add hand-off cost
        res["predict_1_ms_1thread"] = 1e3 * _median_time(lambda: model.predict(w1), r)
        res["predict_features_1_ms_1thread"] = 1e3 * _median_time(
            lambda: model.predict_features(t1), r)
    return res


def run_scaling(args: GSEBenchConfig, kind: str = "", ns: str | None = None
                ) -> list[dict[str, Any]]:
    """Rows of one worker kind ('' = the exact/auto scaling rows, 'scalable',
    'incremental'), each in a fresh subprocess."""
    env = dict(os.environ)
    if args.threads > 0:
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = str(args.threads)
    rows = []
    for n in [int(s) for s in (args.ns if ns is None else ns).split(",") if s.strip()]:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "worker.json"
            worker = GSEBenchConfig(worker_n=n, worker_out=str(out), m=args.m,
                                    seed=args.seed, map_seed=args.map_seed,
                                    n_neighbors=args.n_neighbors, batch_size=args.batch_size,
                                    latency_repeats=args.latency_repeats,
                                    tracemalloc=args.tracemalloc, worker_kind=kind,
                                    compare_n=args.compare_n,
                                    incremental_n=args.incremental_n,
                                    incremental_new=args.incremental_new)
            cmd = [sys.executable, "-m", __spec__.name if __spec__ else __name__,
                   json.dumps(dataclasses.asdict(worker))]
            print(f"[{kind or 'scaling'}] n = {n} ...", flush=True)
            try:
                proc = subprocess.run(cmd, check=False, env=env, cwd=ROOT,
                                      capture_output=True, text=True,
                                      timeout=args.timeout)
                if proc.returncode != 0 or not out.exists():
                    err = (proc.stderr or "").strip().splitlines()[-3:]
                    rows.append({"n": n, "error": " | ".join(err) or f"exit {proc.returncode}"})
                else:
                    rows.append(json.loads(out.read_text()))
            except subprocess.TimeoutExpired:
                rows.append({"n": n, "error": f"timeout after {args.timeout:.0f} s"})
        print(f"          {_fmt_row(rows[-1])}", flush=True)
    return rows


def _fmt_row(r: dict[str, Any]) -> str:
    if "error" in r:
        return f"ERROR: {r['error']}"
    if "partial_fit_s" in r:
        return f"partial_fit {r['partial_fit_s']:.2f} s, refit {r['refit']['fit_s']:.1f} s"
    if "predict_features_1_ms" not in r:
        return (f"fit {r['fit_s']:.2f} s, +{r['peak_rss_delta_mib']:.0f} MiB, predict(1) "
                f"{r['predict_1_ms']:.3f} ms, RRMSE {r['position_rrmse']:.5f}")
    return (f"fit {r['fit_s']:.2f} s, +{r['peak_rss_delta_mib']:.0f} MiB, predict(1) "
            f"{r['predict_1_ms']:.3f} ms, predict_features(1) {r['predict_features_1_ms']:.3f} ms")


def local_exponents(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Slopes of log(fit time) vs log(n) between consecutive sizes."""
    ok = [r for r in rows if "fit_s" in r]
    return [{"n_from": a["n"], "n_to": b["n"],
             "exponent": float(np.log(b["fit_s"] / a["fit_s"]) / np.log(b["n"] / a["n"]))}
            for a, b in itertools.pairwise(ok)]


def growth_exponent(rows: list[dict[str, Any]]) -> float | None:
    ok = [r for r in rows if "fit_s" in r]
    if len(ok) < 2:
        return None
    n = np.log([r["n"] for r in ok])
    t = np.log([r["fit_s"] for r in ok])
    return float(np.polyfit(n, t, 1)[0])


# ---------------------------------------------------------------- report
def targets(args: GSEBenchConfig, scaling: list[dict[str, Any]], expo: float | None) -> list[dict]:
    by_n = {r["n"]: r for r in scaling if "fit_s" in r}
    out = []

    def add(name: str, value: float | None, limit: float, unit: str) -> None:
        status = "NOT RUN" if value is None else ("PASS" if value <= limit else "MISS")
        out.append({"target": name, "value": value, "limit": limit, "unit": unit,
                    "status": status})

    add("fit time n=2500", by_n.get(2500, {}).get("fit_s"), 20.0, "s")
    add("fit time n=10000", by_n.get(10000, {}).get("fit_s"), 60.0, "s")
    add("growth exponent of fit time", expo, 2.0, "")
    n_lat = args.latency_n if args.latency_n in by_n else (max(by_n) if by_n else None)
    lat = by_n.get(n_lat, {})
    add(f"predict, one query (n={n_lat})", lat.get("predict_1_ms"), 1.0, "ms")
    add(f"predict_features, one query (n={n_lat})", lat.get("predict_features_1_ms"), 1.0, "ms")
    add(f"predict, one query, 1 BLAS thread (n={n_lat})", lat.get("predict_1_ms_1thread"), 1.0,
        "ms")
    add(f"predict_features, one query, 1 BLAS thread (n={n_lat})",
        lat.get("predict_features_1_ms_1thread"), 1.0, "ms")
    return out


def _scale_parts(args: GSEBenchConfig, res: dict[str, Any]) -> None:
    """The scalable-path rows and the partial_fit run (issue 13), into ``res``."""
    res["scalable"] = [] if args.skip_scalable else run_scaling(args, "scalable", args.scale_ns)
    res["scalable_summary"] = scalable_summary(res["scalable"])
    res["incremental"] = None if args.skip_incremental else run_scaling(
        args, "incremental", str(args.incremental_n))[0]
    for name, value, limit, unit in scale_targets(res["scalable"], res["scalable_summary"],
                                                  res["incremental"]):
        status = "NOT RUN" if value is None else ("PASS" if value <= limit else "MISS")
        res["targets"].append({"target": name, "value": value, "limit": limit, "unit": unit,
                               "status": status})


def markdown(args: GSEBenchConfig, res: dict[str, Any]) -> str:
    lines = [f"# GSE benchmark ({'quick' if args.quick else 'full'} run, {res['meta']['date']})",
             "", (f"Synthetic regression manifold, m = {args.m}, GSE n_neighbors = "
             f"{args.n_neighbors}; {res['meta']['cpu_count']} CPUs, threads = "
             f"{args.threads or 'inherited'}; memory = peak RSS growth during fit "
             "(ru_maxrss)."), ""]
    if res["scaling"]:
        lines += ["## Fit time, memory and latency vs n (dim_theta = 3)", "",
                  (f"Single-query latency: worker BLAS threads "
                   f"({args.threads or 'inherited'}) / 1 thread."), "",
                  ("| n | fit (s) | peak RSS +MiB | predict 1 (ms) | predict_features 1 (ms) | "
                   f"predict {args.batch_size} (ms) | predict_features {args.batch_size} (ms) |"),
                  "|---|---|---|---|---|---|---|"]
        for r in res["scaling"]:
            if "error" in r:
                lines.append(f"| {r['n']} | error: {r['error']} | | | | | |")
                continue
            lines.append(f"| {r['n']} | {r['fit_s']:.2f} | {r['peak_rss_delta_mib']:.0f} | "
                         f"{r['predict_1_ms']:.3f} / {r['predict_1_ms_1thread']:.3f} | "
                         f"{r['predict_features_1_ms']:.3f} / "
                         f"{r['predict_features_1_ms_1thread']:.3f} | "
                         f"{r['predict_batch_ms']:.1f} | {r['predict_features_batch_ms']:.1f} |")
        local = ", ".join(f"{e['n_from']}->{e['n_to']}: {e['exponent']:.2f}"
                          for e in res["local_growth_exponents"])
        lines += ["", ("Growth exponent of fit time vs n (least squares over all n): "
                       f"{fmt_value(res['growth_exponent'], '{:.2f}')}; between consecutive n: {local}"),
                  ""]
    if res["accuracy"]:
        lines += ["## Accuracy (RRMSE; lower is better)", "",
                  ("| dim_theta | method | psi* position RRMSE | heading RMSE (rad) | Phi* RRMSE | "
                  "fit (s) | note |"), "|---|---|---|---|---|---|---|"]
        for r in res["accuracy"]:
            note = r.get("error", "")
            if "k" in r:
                note = f"k = {r['k']}"
            elif "knr_bandwidth" in r:
                note = f"h = {r['knr_bandwidth']:.3g}"
            lines.append(f"| {r['dim_theta']} | {r['method']} | "
                         f"{fmt_value(r.get('psi_position_rrmse'), '{:.4f}')} | "
                         f"{fmt_value(r.get('heading_rmse_rad'), '{:.4f}')} | "
                         f"{fmt_value(r.get('phi_rrmse'), '{:.4f}')} | {fmt_value(r.get('fit_s'), '{:.2f}')} | "
                         f"{note} |")
        lines.append("")
    if res.get("scalable"):
        lines += scalable_markdown(res["scalable"], res["scalable_summary"])
    if res.get("incremental"):
        lines += incremental_markdown(res["incremental"])
    if res["targets"]:
        lines += ["## Targets", "", "| target | value | limit | status |", "|---|---|---|---|"]
        for t in res["targets"]:
            u = f" {t['unit']}" if t["unit"] else ""
            lines.append(f"| {t['target']} | {fmt_value(t['value'], '{:.3f}')}{u} | "
                         f"<= {t['limit']:g}{u} | {t['status']} |")
        lines.append("")
    return "\n".join(lines)


def run_gse_bench(args: GSEBenchConfig) -> dict[str, Any]:
    """Run the benchmark (scaling workers in fresh subprocesses, then the accuracy part in
    this process); write ``<out>.json`` / ``<out>.md``; return the result."""
    args = args.resolved()
    if args.worker_n:
        worker = {"": run_worker, "scalable": scalable_worker,
                  "incremental": incremental_worker}[args.worker_kind]
        Path(args.worker_out).write_text(json.dumps(worker(args), default=float))
        return {}
    res: dict[str, Any] = {"args": dataclasses.asdict(args), "meta": {
        "date": time.strftime("%Y-%m-%d %H:%M:%S"), **provenance(),
        "cpu_count": os.cpu_count(), "memory_measure": "ru_maxrss growth during fit, "
        "fresh subprocess per n"}}
    t0 = time.perf_counter()
    res["scaling"] = [] if args.skip_scaling else run_scaling(args)
    res["growth_exponent"] = growth_exponent(res["scaling"])
    res["local_growth_exponents"] = local_exponents(res["scaling"])
    if args.skip_accuracy:
        res["accuracy"] = []
    else:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(args.threads if args.threads > 0 else None):
            res["accuracy"] = run_accuracy(args)
    res["targets"] = targets(args, res["scaling"], res["growth_exponent"]) \
        if res["scaling"] else []
    _scale_parts(args, res)
    res["meta"]["total_s"] = time.perf_counter() - t0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(res, indent=2, default=float))
    md = markdown(args, res)
    out.with_suffix(".md").write_text(md + "\n")
    print("\n" + md)
    for t in res["targets"]:
        u = f" {t['unit']}" if t["unit"] else ""
        print(f"{t['status']:8s} {t['target']}: {fmt_value(t['value'], '{:.3f}')}{u} "
              f"(limit {t['limit']:g}{u})")
    print(f"\nwrote {out.with_suffix('.json')} and {out.with_suffix('.md')}")
    return res


if __name__ == "__main__":  # a scaling worker: python -m ... '<GSEBenchConfig as JSON>'
    run_gse_bench(GSEBenchConfig(**json.loads(sys.argv[1])))
