"""The scalable and incremental parts of the GSE benchmark (``appearance-nav bench --only gse``;
settings in :class:`~localization.workflows.benchmarks.gse.GSEBenchConfig`).

* Scalable path (one fresh subprocess per n, like the scaling rows): data
  ``regression_manifold(n, dim_theta=3, m)`` (synthetic, not rendered), ``GSERegressor(
  periodic=(2,), algorithm="approximate")``: wall-clock fit time, peak RSS growth during
  the fit (``ru_maxrss``), one ``predict`` query (median of ``latency_repeats``, inside
  ``threadpool_limits(1)``), position RRMSE / heading RMSE on ``batch_size`` held-out
  samples, and the recall of the approximate neighbours: of the kNN graph of Z (1000 rows
  checked against a brute force) and of the feature-space queries of ``predict`` (the
  held-out rows). At n = ``compare_n`` the exact path is fitted on the same data too
  (``algorithm="exact"``): its time and RRMSE side by side. Growth exponent: least-squares
  slope of log(fit time) over the scalable rows.
* Incremental GSE: a base model on ``incremental_n`` samples with x in [0, 1], then
  ``incremental_new`` samples of a new strip x in [1, 1 + new/n] (a new street, at the same
  density) added by ``partial_fit`` (timed), against a refit on the union (timed);
  position RRMSE / heading RMSE of both on held-out samples of the union and of the strip.
"""

from __future__ import annotations

import resource
import time
import warnings
from typing import Any

import numpy as np

__all__ = ["incremental_worker", "scalable_worker"]


def _median_ms(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def _scores(model: Any, W: np.ndarray, T: np.ndarray) -> dict[str, float]:
    from localization.metrics import angular_rmse, rrmse

    P = model.predict(W)
    ok = np.isfinite(P).all(axis=1)
    return {"position_rrmse": rrmse(P[ok], T[ok], columns=(0, 1)),
            "heading_rmse_rad": angular_rmse(P[ok, 2], T[ok, 2]),
            "out_of_domain": int((~ok).sum())}


def _timed_fit(model: Any, W: np.ndarray, T: np.ndarray) -> dict[str, Any]:
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        model.fit(W, T)
        fit_s = time.perf_counter() - t0
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {"fit_s": fit_s, "peak_rss_delta_mib": (rss1 - rss0) / 1024.0,
            "peak_rss_mib": rss1 / 1024.0,
            "fit_warnings": sorted({str(w.message)[:120] for w in caught})}


def _recall(found: np.ndarray, true: np.ndarray) -> float:
    k = true.shape[1]
    return float(np.mean([len(set(a) & set(b)) / k for a, b in zip(found, true, strict=True)]))


def _graph_recall(model: Any, rows: int = 1000) -> float:
    """Recall of the GSE kNN graph of Z on ``rows`` random rows, against a brute force."""
    from localization.gse.graph import brute_knn

    g = model.gse_
    Z = g.Z_
    sel = np.random.default_rng(0).choice(len(Z), min(rows, len(Z)), replace=False)
    _, ind = brute_knn(Z, (Z ** 2).sum(axis=1), Z[sel], g.n_neighbors + 1)
    return _recall(np.sort(g.neighbors_[sel], 1), np.sort(ind[:, 1:], 1))


def _query_recall(model: Any, W: np.ndarray) -> float:
    """Recall of the feature-space neighbours of ``predict`` on held-out rows."""
    from localization.gse.graph import brute_knn

    Ws = (W - model.w_mean_) / model.w_scale_
    found = model._query_w(Ws, model.jr_neighbors_)[1]
    _, true = brute_knn(model._ws, model._ws_sqn, Ws, model.jr_neighbors_)
    return _recall(found, true)


def scalable_worker(args: Any) -> dict[str, Any]:
    """One scalable-path row at n = ``args.worker_n`` (a fresh process)."""
    from threadpoolctl import threadpool_limits

    from localization.gse.regressor import GSERegressor
    from localization.synthetic import regression_manifold

    n = args.worker_n
    W, T, _ = regression_manifold(n, dim_theta=3, m=args.m, seed=args.seed, map_seed=args.map_seed)
    Wt, Tt, _ = regression_manifold(args.batch_size, dim_theta=3, m=args.m, seed=args.seed + 1,
                                    map_seed=args.map_seed)
    Ww, Tw, _ = regression_manifold(2000, dim_theta=3, m=args.m, seed=args.seed + 2,
                                    map_seed=args.map_seed)
    with warnings.catch_warnings():  # untimed warm-up: imports, faiss / pyamg first calls
        warnings.simplefilter("ignore")
        GSERegressor(periodic=(2,), algorithm="approximate").fit(Ww, Tw)
    params = {"periodic": (2,), "n_neighbors": args.n_neighbors, "random_state": args.seed,
              "out_of_domain": "nan"}
    model = GSERegressor(algorithm="approximate", **params)
    res: dict[str, Any] = {"n": n, "algorithm": "approximate", **_timed_fit(model, W, T)}
    res.update(_scores(model, Wt, Tt))
    w1 = Wt[:1]
    model.predict(w1)
    with threadpool_limits(1):
        res["predict_1_ms"] = _median_ms(lambda: model.predict(w1), args.latency_repeats)
    res["predict_batch_ms"] = _median_ms(lambda: model.predict(Wt), 3)
    res["graph_recall"] = _graph_recall(model)
    res["query_recall"] = _query_recall(model, Wt)
    if n == args.compare_n:
        exact = GSERegressor(algorithm="exact", **params)
        res["exact"] = {**_timed_fit(exact, W, T), **_scores(exact, Wt, Tt)}
        exact.predict(w1)
        with threadpool_limits(1):
            res["exact"]["predict_1_ms"] = _median_ms(lambda: exact.predict(w1),
                                                      args.latency_repeats)
    return res


def _strip_data(n: int, x0: float, x1: float, m: int, seed: int, map_seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    from localization.synthetic import FeatureMap

    rng = np.random.default_rng(seed)
    T = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(0.0, 1.0, n),
                         rng.uniform(-np.pi, np.pi, n)])
    return FeatureMap(3, m=m, seed=map_seed, periodic=(2,))(T), T


def incremental_worker(args: Any) -> dict[str, Any]:
    """partial_fit of ``incremental_new`` samples into an ``incremental_n`` model, against a
    refit on the union (a fresh process)."""
    from localization.gse.regressor import GSERegressor

    n0, n_new = args.incremental_n, args.incremental_new
    x1 = 1.0 + n_new / n0
    W0, T0 = _strip_data(n0, 0.0, 1.0, args.m, args.seed, args.map_seed)
    W1, T1 = _strip_data(n_new, 1.0, x1, args.m, args.seed + 1, args.map_seed)
    tests = {"union": _strip_data(args.batch_size, 0.0, x1, args.m, args.seed + 2,
                                  args.map_seed),
             "new strip": _strip_data(args.batch_size, 1.0, x1, args.m, args.seed + 3,
                                      args.map_seed)}
    params = {"periodic": (2,), "n_neighbors": args.n_neighbors, "random_state": args.seed,
              "out_of_domain": "nan"}
    base = GSERegressor(**params)
    res: dict[str, Any] = {"n_base": n0, "n_new": n_new, "base": _timed_fit(base, W0, T0)}
    res["algorithm"] = base.algorithm_
    res["base"].update({k: _scores(base, *v) for k, v in tests.items()})
    t0 = time.perf_counter()
    base.partial_fit(W1, T1)
    res["partial_fit_s"] = time.perf_counter() - t0
    res["rows_updated"] = len(base.partial_fit_rows_)
    res["incremental"] = {k: _scores(base, *v) for k, v in tests.items()}
    refit = GSERegressor(**params)
    res["refit"] = _timed_fit(refit, np.vstack([W0, W1]), np.vstack([T0, T1]))
    res["refit"].update({k: _scores(refit, *v) for k, v in tests.items()})
    return res


def scalable_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Growth exponent of the scalable rows' fit time (least squares in log-log)."""
    ok = [r for r in rows if "fit_s" in r]
    expo = (float(np.polyfit(np.log([r["n"] for r in ok]), np.log([r["fit_s"] for r in ok]),
                             1)[0]) if len(ok) >= 2 else None)
    return {"growth_exponent": expo,
            "n_range": [ok[0]["n"], ok[-1]["n"]] if ok else None}


def fmt_value(x: Any, fmt: str = "{:.3f}") -> str:
    """``x`` formatted, "-" for None (the GSE benchmark's table cells)."""
    return "-" if x is None else fmt.format(x)


def scalable_markdown(rows: list[dict[str, Any]], summary: dict[str, Any]) -> list[str]:
    lines = ["## Scalable path (algorithm=\"approximate\"; faiss HNSW + AMG-LOBPCG/CG)", "",
             ("| n | fit (s) | peak RSS +MiB | predict 1 (ms, 1 thread) | position RRMSE | "
              "heading RMSE (rad) | kNN graph recall | query recall |"),
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['n']} | error: {r['error']} | | | | | | |")
            continue
        lines.append(f"| {r['n']} | {r['fit_s']:.1f} | {r['peak_rss_delta_mib']:.0f} | "
                     f"{r['predict_1_ms']:.3f} | {r['position_rrmse']:.5f} | "
                     f"{r['heading_rmse_rad']:.4f} | {r['graph_recall']:.4f} | "
                     f"{r['query_recall']:.4f} |")
        if "exact" in r:
            e = r["exact"]
            lines.append(f"| {r['n']} (exact path) | {e['fit_s']:.1f} | "
                         f"{e['peak_rss_delta_mib']:.0f} | {e['predict_1_ms']:.3f} | "
                         f"{e['position_rrmse']:.5f} | {e['heading_rmse_rad']:.4f} | 1 | 1 |")
    lines += ["", (f"Growth exponent of the scalable fit time over n = {summary['n_range']}: "
                   f"{fmt_value(summary['growth_exponent'], '{:.2f}')}"), ""]
    return lines


def incremental_markdown(r: dict[str, Any]) -> list[str]:
    if "error" in r:
        return ["## Incremental GSE (partial_fit)", "", f"error: {r['error']}", ""]
    lines = ["## Incremental GSE (partial_fit)", "",
             (f"{r['n_new']} samples of a new strip added to a {r['n_base']}-sample model "
              f"({r['algorithm']} path): partial_fit {r['partial_fit_s']:.2f} s "
              f"({r['rows_updated']} rows updated) against a refit on the union "
              f"{r['refit']['fit_s']:.1f} s."), "",
             "| model | test set | position RRMSE | heading RMSE (rad) | out of domain |",
             "|---|---|---|---|---|"]
    for name in ("base", "incremental", "refit"):
        for test in ("union", "new strip"):
            s = r[name][test]
            lines.append(f"| {name} | {test} | {s['position_rrmse']:.5f} | "
                         f"{s['heading_rmse_rad']:.4f} | {s['out_of_domain']} |")
    return [*lines, ""]


def scale_targets(rows: list[dict[str, Any]], summary: dict[str, Any],
                  inc: dict[str, Any] | None) -> list[tuple[str, float | None, float, str]]:
    """(target, value, limit, unit) of issue 13's scalable and incremental GSE."""
    by_n = {r["n"]: r for r in rows if "fit_s" in r}
    top = by_n.get(100000, {})
    out: list[tuple[str, float | None, float, str]] = [
        ("scalable fit n=100000", top.get("fit_s"), 120.0, "s"),
        ("scalable fit peak RSS growth n=100000", top.get("peak_rss_delta_mib"), 8192.0, "MiB"),
        ("scalable predict, one query (n=100000)", top.get("predict_1_ms"), 2.0, "ms"),
        (f"growth exponent of the scalable fit, n={summary['n_range']}",
         summary["growth_exponent"], 1.15, ""),
    ]
    cmp = [r for r in rows if "exact" in r]
    if cmp:
        r = cmp[0]
        out.append((f"scalable / exact position RRMSE (n={r['n']})",
                    r["position_rrmse"] / r["exact"]["position_rrmse"], 1.05, ""))
    if inc and "partial_fit_s" in inc:
        out.append((f"partial_fit {inc['n_new']} into {inc['n_base']}", inc["partial_fit_s"],
                    2.0, "s"))
        for test in ("union", "new strip"):
            out.append((f"partial_fit / refit position RRMSE ({test})",
                        inc["incremental"][test]["position_rrmse"]
                        / inc["refit"][test]["position_rrmse"], 1.05, ""))
    return out
