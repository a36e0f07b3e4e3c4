"""The accuracy part of the GSE benchmark (``appearance-nav bench --only gse``): GSE against
KNR and kNN retrieval, both directions (psi*: features -> pose; Phi*: pose -> features), on
:func:`localization.synthetic.regression_manifold` data.
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

__all__ = ["run_accuracy"]


def _lift_pose(T: np.ndarray) -> np.ndarray:
    """Pose -> input features for the baselines' Phi: yaw as (cos, sin)."""
    if T.shape[1] == 3:
        return np.column_stack([T[:, :2], np.cos(T[:, 2]), np.sin(T[:, 2])])
    return T


def run_accuracy(args: Any) -> list[dict[str, Any]]:
    """GSE, KNR and retrieval on the same synthetic regression manifolds (``args``: a
    :class:`~localization.workflows.benchmarks.gse.GSEBenchConfig`): psi*'s position RRMSE
    and heading RMSE, Phi*'s RRMSE, one row per method and pose dimension."""
    from localization.baselines import KernelRegressor, RetrievalRegressor
    from localization.gse.regressor import GSERegressor
    from localization.metrics import angular_rmse, rrmse
    from localization.synthetic import regression_manifold

    rows = []
    for dim in [int(s) for s in args.accuracy_dims.split(",") if s.strip()]:
        W, T, phi = regression_manifold(args.accuracy_n_train, dim_theta=dim, m=args.m,
                                        seed=args.seed, map_seed=args.map_seed)
        Wt, Tt, _ = regression_manifold(args.accuracy_n_test, dim_theta=dim, m=args.m,
                                        seed=args.seed + 1, map_seed=args.map_seed)
        per = (2,) if dim == 3 else ()
        Wtrue = phi(Tt)
        models: dict[str, tuple[Any, Any]] = {
            "GSE": (GSERegressor(periodic=per, n_neighbors=args.n_neighbors,
                                 random_state=args.seed), None),
            "KNR": (KernelRegressor(periodic=per), KernelRegressor()),
            "retrieval k=1": (RetrievalRegressor(n_neighbors=1, periodic=per),
                              RetrievalRegressor(n_neighbors=1)),
            "retrieval k=cv": (RetrievalRegressor(n_neighbors="cv", periodic=per),
                               RetrievalRegressor(n_neighbors="cv")),
        }
        for name, (loc, fm) in models.items():
            row: dict[str, Any] = {"dim_theta": dim, "method": name, "n_train": len(W),
                                   "n_test": len(Wt)}
            print(f"[accuracy] dim_theta={dim} {name} ...", flush=True)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    loc.fit(W, T)
                    row["fit_s"] = time.perf_counter() - t0
                    pred = loc.predict(Wt)
                    if fm is None:  # GSE: one model gives both directions
                        wpred = loc.predict_features(Tt)
                    else:
                        wpred = fm.fit(_lift_pose(T), W).predict(_lift_pose(Tt))
                row["psi_position_rrmse"] = rrmse(pred, Tt, columns=(0, 1))
                row["heading_rmse_rad"] = angular_rmse(pred[:, 2], Tt[:, 2]) if dim == 3 else None
                row["phi_rrmse"] = rrmse(wpred, Wtrue)
                if hasattr(loc, "bandwidth_"):
                    row["knr_bandwidth"] = loc.bandwidth_
                if getattr(loc, "n_neighbors_", None) is not None and name.startswith("retr"):
                    row["k"] = loc.n_neighbors_
            except Exception as exc:  # noqa: BLE001  (report, keep benchmarking the others)
                row["error"] = f"{type(exc).__name__}: {exc}"[:200]
            rows.append(row)
    return rows
