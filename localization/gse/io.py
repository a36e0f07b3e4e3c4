"""Persistence of :class:`~localization.gse.regressor.GSERegressor` (npz, no pickles)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from localization.gse.embedding import GrassmannStiefelEigenmaps

_ARRAYS = ("w_mean_", "theta_center_", "theta_scale_", "theta_", "Gr_", "GR_", "Z_", "tangents_",
           "frames_", "embedding_", "alignment_eigenvalues_", "frame_condition_")


def save_regressor(model: Any, path: str | Path) -> None:
    """Write a fitted regressor: arrays plus a JSON settings string."""
    g = model.gse_
    settings = {
        "params": {k: (list(v) if isinstance(v, tuple) else v)
                   for k, v in model.get_params().items()},
        "gse_params": g.get_params(), "w_scale_": model.w_scale_,
        "bandwidth_w_": model.bandwidth_w_, "bandwidth_theta_": model.bandwidth_theta_,
        "jr_neighbors_": model.jr_neighbors_, "pca_bw": model._pca_bw,
        "gse_bandwidth_": g.bandwidth_, "recovery_bandwidth_": g.recovery_bandwidth_,
        "n_edges_": g.n_edges_, "agreement_": model.agreement_,
        "y_1d": bool(getattr(model, "y_1d_", False)), "algorithm_": g.algorithm_, "format": 3}
    if isinstance(settings["params"]["theta_scale"], np.ndarray):
        settings["params"]["theta_scale"] = settings["params"]["theta_scale"].tolist()
    arrays = {k: getattr(model, k) if hasattr(model, k) else getattr(g, k) for k in _ARRAYS}
    arrays["cut_"] = np.zeros(0) if g.cut_ is None else g.cut_
    arrays["loop_angle_"] = np.zeros(0) if model.loop_angle_ is None else model.loop_angle_
    arrays["w_radius_"], arrays["theta_radius_"] = model.w_radius_, model.theta_radius_
    arrays["neighbors_"] = g.neighbors_  # the kNN lists partial_fit updates (format 3)
    arrays["neighbor_distances_"] = g.neighbor_distances_
    precision = getattr(model, "feature_precision_", None)  # first_order="forward"
    arrays["feature_precision_"] = np.zeros((0, 0)) if precision is None else precision
    np.savez(path, settings=np.array(json.dumps(settings)), **arrays)


def load_regressor(cls: Any, path: str | Path) -> Any:
    """Rebuild a regressor written by :func:`save_regressor`; ValueError if the file is
    corrupted or incomplete."""
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
        s = json.loads(str(data["settings"]))
        p = s["params"]
        p["periodic"] = tuple(p["periodic"])
        p["bandwidth_grid"] = tuple(p["bandwidth_grid"])
        model = cls(**p)
        g = GrassmannStiefelEigenmaps(**s["gse_params"])
        for k in _ARRAYS:
            setattr(model if k.endswith(("mean_", "center_", "scale_")) or k in
                    ("theta_", "Gr_", "GR_") else g, k, np.asarray(data[k], dtype=np.float64))
        cut = data["cut_"]
        g.cut_ = (cut[:, None] if cut.ndim == 1 else cut) if cut.size else None
        model.cut_ = g.cut_
        la = data.get("loop_angle_")
        model.loop_angle_ = la if la is not None and la.size else None
        n_s = len(data["theta_"])
        for key in ("w_radius_", "theta_radius_"):  # format 1 files predate them: only the
            # (then nonexistent) adaptive_bandwidth option reads them
            value = data.get(key, np.full(n_s, np.nan))
            setattr(model, key, np.asarray(value, dtype=np.float64))
            if getattr(model, key).shape != (n_s,):
                raise ValueError(f"{key} has the wrong shape")
        g.bandwidth_, g.n_edges_ = float(s["gse_bandwidth_"]), int(s["n_edges_"])
        g.recovery_bandwidth_ = float(s["recovery_bandwidth_"])
        g.n_components_graph_ = 1
        g.algorithm_ = model.algorithm_ = str(s.get("algorithm_", "exact"))  # format < 3: exact
        if "neighbors_" in data:
            g.neighbors_ = np.asarray(data["neighbors_"], dtype=np.intp)
            g.neighbor_distances_ = np.asarray(data["neighbor_distances_"], dtype=np.float64)
            if (g.neighbors_.shape != g.neighbor_distances_.shape
                    or g.neighbors_.shape[0] != len(data["theta_"])
                    or g.neighbors_.size and not 0 <= g.neighbors_.min() <= g.neighbors_.max()
                    < len(data["theta_"])):
                raise ValueError("neighbors_ has the wrong shape or indices")
        model.w_scale_ = float(s["w_scale_"])
        model.y_1d_ = bool(s.get("y_1d", False))  # absent from older files: 2-D poses
        model.agreement_ = s.get("agreement_")
        model.jr_neighbors_ = int(s["jr_neighbors_"])
        model._pca_bw = float(s["pca_bw"])
        model.bandwidth_w_, model.bandwidth_theta_ = (float(s["bandwidth_w_"]),
                                                    float(s["bandwidth_theta_"]))
        n, p_, q = g.frames_.shape
        m, d = len(model.w_mean_), len(model.theta_scale_)
        model._per = model._periodic(d)
        shapes_ok = (g.Z_.shape == (n, p_) and g.tangents_.shape == (n, p_, q)
                     and g.embedding_.shape == (n, q) and model.theta_.shape == (n, d)
                     and model.Gr_.shape == (n, q, m) and model.GR_.shape == (n, q, d)
                     and p_ == m + d + len(model._per)
                     and (g.cut_ is None or g.cut_.shape[0] == n))
        precision = data.get("feature_precision_", np.zeros((0, 0)))
        model.feature_precision_ = (np.asarray(precision, dtype=np.float64) if precision.size
                                    else None)
        shapes_ok &= (model.feature_precision_ is None) == (model.first_order == "frames") and (
            model.feature_precision_ is None or model.feature_precision_.shape == (m, m))
        if not shapes_ok:
            raise ValueError("inconsistent array shapes")
        if not all(np.isfinite(getattr(model if hasattr(model, k) else g, k)).all()
                   for k in ("Z_", "frames_", "embedding_", "Gr_", "GR_")):
            raise ValueError("non-finite values")
    except Exception as exc:  # zipfile, KeyError, JSON, shape errors -> one clear message
        raise ValueError(f"cannot load GSERegressor from {path}: corrupted or incomplete "
                         f"file ({type(exc).__name__}: {exc})") from exc
    g.n_features_in_, model.n_features_in_ = g.Z_.shape[1], m
    g._setup()
    model.gse_ = g
    model._setup()
    model._w_tangents = np.linalg.qr(g.frames_[:, :m, :])[0]
    s = np.linalg.svd(g.frames_[:, m:, :], compute_uv=False)
    model.pose_condition_ = s[:, 0] / np.maximum(s[:, -1], np.finfo(float).tiny)
    return model
