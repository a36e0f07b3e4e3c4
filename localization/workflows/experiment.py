"""The paper's localization experiment (section V, Table II) on prepared features.

For one data set (features ``W`` and poses of a train and a test split) fit and score
the three regressors features -> pose of Table II, every hyper-parameter chosen on the
*training* split only:

- ``"gse"``: :class:`~localization.gse.regressor.GSERegressor` (psi*), ``n_neighbors`` by
  K-fold CV (:func:`~localization.model_selection.grid_search`), JR bandwidths and the
  agreement scale by leave-one-out inside ``fit``. ``theta_scale_factor=100``: image
  features are rough at the sampling scale (a robot turning changes the picture fast),
  and unless the pose dominates the Z-space neighbourhoods the local tangents follow the
  roughness and the q=1 frames flip along the route (the embedding folds; measured on the
  perspective route: factor 2 CV RRMSE 0.5-0.8, 20 and 100 0.04-0.13, and with ImageNet
  features only 100 avoids a fold: test 0.21 vs 0.72);
- ``"knr"``: :class:`~localization.baselines.KernelRegressor` (the paper's KNR: one
  global LOO bandwidth), feature standardisation on/off by CV;
- ``"knn"``: :class:`~localization.baselines.RetrievalRegressor` (image retrieval), k by
  CV inside ``fit``, standardisation by CV;
- ``"gse_verified"`` (with ``verify`` > 0, the same fitted GSE): psi*(w) checked against the
  poses of the ``verify`` training images nearest in feature space and replaced by one whose
  Phi* explains w ``verify_margin`` times better
  (:func:`~localization.gse.inverse.verify_poses`, the whitener from the training split's
  own residuals about Phi*, :func:`~localization.gse.inverse.residual_whitener`): the
  retrieve-and-verify step of :meth:`AppearanceLocalizer.predict(verify=...)
  <localization.localizer.AppearanceLocalizer.predict>`, for gross errors of psi* (a fold,
  a look-alike place).

The feature dimension (leading PCA components) is chosen per method by the same CV
(``feature_dims``), and so is the feature *variant* (``variants``: e.g. the same PCA features
whitened, :func:`whitened`).

Errors: position RRMSE (:func:`~localization.metrics.rrmse` over x, y), median / 95th
percentile / max position error in metres, and the heading RMSE when poses have a yaw.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from localization._validation import check_int, check_real
from localization.baselines import KernelRegressor, RetrievalRegressor
from localization.geometry import Array
from localization.gse.inverse import residual_whitener, verify_poses
from localization.gse.regressor import GSERegressor
from localization.metrics import angular_rmse, rrmse
from localization.model_selection import grid_search

__all__ = ["GSE_GRID", "MethodResult", "evaluate_methods", "fit_gse", "position_errors",
           "whitened"]

#: CV grid of the GSE regressor (JR bandwidth factors of the adaptive kernel: own grid).
GSE_GRID: dict[str, list[Any]] = {"n_neighbors": [10, 20], "theta_scale_factor": [100.0]}
#: Factors of the adaptive JR bandwidth tried by leave-one-out. From 0.03: on the perspective
#: route with ImageNet features (city 0's training split) LOO chose 0.1, the old grid's edge.
ADAPTIVE_GRID = (0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5, 0.7, 1.0)


@dataclass
class MethodResult:
    """Test errors of one method on one data set."""

    method: str
    rrmse: float
    median_m: float
    p95_m: float
    max_m: float
    heading_rmse: float | None
    params: dict[str, Any] = field(default_factory=dict)
    cv: list[dict[str, Any]] = field(default_factory=list)
    fit_s: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def position_errors(pred: Array, true: Array) -> dict[str, float]:
    """RRMSE over the position columns (x, y) and error quantiles in metres."""
    e = np.linalg.norm(pred[:, :2] - true[:, :2], axis=1)
    return {"rrmse": rrmse(pred[:, :2], true[:, :2]), "median_m": float(np.median(e)),
            "p95_m": float(np.percentile(e, 95)), "max_m": float(e.max())}


def whitened(W_tr: Array, W_te: Array) -> tuple[Array, Array]:
    """Both splits scaled by the training columns' standard deviations (PCA whitening for
    PCA features: every component then weighs the same in distances)."""
    sd = np.asarray(W_tr, dtype=np.float64).std(axis=0)
    sd = np.where(sd > 0, sd, 1.0)
    return W_tr / sd, W_te / sd


def _gse(q: int, periodic: tuple[int, ...], seed: int, **params: Any) -> GSERegressor:
    return GSERegressor(n_components=q, periodic=periodic, adaptive_bandwidth=True,
                        agreement="auto", bandwidth_grid=ADAPTIVE_GRID,
                        out_of_domain="ignore", random_state=seed, **params)


def fit_gse(W: Array, P: Array, q: int, periodic: tuple[int, ...] = (), cv: int = 3,
            grid: dict[str, list[Any]] | None = None, seed: int = 0
            ) -> tuple[GSERegressor, dict[str, Any], list[dict[str, Any]]]:
    """GSERegressor with ``grid`` (default :data:`GSE_GRID`) chosen by CV, refitted on all
    of ``W``, ``P``. Returns the model, the chosen parameters and the CV table."""
    grid = GSE_GRID if grid is None else grid
    best, rows = grid_search(_gse(q, periodic, seed), grid, W, P, cv, columns=(0, 1),
                             random_state=seed)
    return _gse(q, periodic, seed, **best).fit(W, P), best, rows


def evaluate_methods(W_tr: Array, P_tr: Array, W_te: Array, P_te: Array, q: int,
                     periodic: tuple[int, ...] = (), cv: int = 3, seed: int = 0,
                     gse_grid: dict[str, list[Any]] | None = None,
                     methods: tuple[str, ...] = ("gse", "knr", "knn"),
                     feature_dims: tuple[int, ...] | None = None,
                     variants: dict[str, tuple[Array, Array]] | None = None,
                     verify: int = 0, verify_margin: float = 3.0,
                     ) -> tuple[list[MethodResult], dict[str, Array], dict[str, Any]]:
    """Fit every method on the training split (hyper-parameters by CV there) and score it
    on the test split. Returns the results, the test predictions and the fitted models,
    both by method name.

    ``feature_dims``: candidate feature dimensions m, chosen per method by the same CV
    (the leading m columns: the features must be ordered by importance, like PCA
    components); None uses all columns. A model in the returned dict takes the leading
    ``params["n_features"]`` columns.

    ``variants``: other versions of the features, name -> (train, test) arrays of the same
    shapes (e.g. :func:`whitened`), tried beside ``"plain"`` (``W_tr``, ``W_te``); each
    method's CV chooses one, recorded in ``params["variant"]`` (only when variants are given).

    ``verify`` > 0 (with "gse" among the methods): also ``"gse_verified"``, the same GSE
    model's psi* verified against ``verify`` retrieved training poses with
    ``verify_margin`` (see the module docstring); no extra fit.
    """
    verify = check_int(verify, "verify", low=0)
    verify_margin = check_real(verify_margin, "verify_margin", low=1.0)
    out, preds, models = [], {}, {}
    dims = [W_tr.shape[1]] if feature_dims is None else sorted(
        {min(int(m), W_tr.shape[1]) for m in feature_dims})
    sets = {"plain": (W_tr, W_te), **(variants or {})}
    for vname, (Vtr, Vte) in sets.items():
        if np.shape(Vtr) != np.shape(W_tr) or np.shape(Vte) != np.shape(W_te):
            raise ValueError(f"variants[{vname!r}] must have the shapes of W_tr, W_te "
                             f"{np.shape(W_tr)}, {np.shape(W_te)}; got {np.shape(Vtr)}, "
                             f"{np.shape(Vte)}")
    for name in methods:
        t0 = time.perf_counter()
        try:
            best = None
            for vname, (Vtr, _) in sets.items():
                for m in dims:
                    model, params, rows = _fit_method(name, Vtr[:, :m], P_tr, q, periodic, cv,
                                                      seed, gse_grid)
                    score = min(r["rrmse"] for r in rows)
                    tag = {"n_features": m, **({"variant": vname} if variants else {})}
                    rows = [{**r, **tag} for r in rows]
                    if best is None or score < best[0]:
                        best = (score, model, {**params, **tag}, rows + best[3] if best
                                else rows)
                    else:
                        best = (*best[:3], best[3] + rows)
            _, model, params, rows = best  # type: ignore[misc]
        except ValueError as exc:  # e.g. every GSE candidate has a disconnected graph
            nan = float("nan")
            out.append(MethodResult(name, nan, nan, nan, nan, nan if P_te.shape[1] > 2 else None,
                                    params={"error": str(exc).strip().splitlines()[-1][:300]},
                                    fit_s=time.perf_counter() - t0))
            continue
        fit_s = time.perf_counter() - t0
        test = sets[params.get("variant", "plain")][1]
        pred = np.asarray(model.predict(test[:, :params["n_features"]]), dtype=np.float64)
        preds[name], models[name] = pred, model
        heading = angular_rmse(pred[:, 2], P_te[:, 2]) if P_te.shape[1] > 2 else None
        out.append(MethodResult(name, heading_rmse=heading, params=params, cv=rows,
                                fit_s=fit_s, **position_errors(pred, P_te)))
        if name == "gse" and verify:
            sets_m = [a[:, :params["n_features"]] for a in sets[params.get("variant", "plain")]]
            t0 = time.perf_counter()
            pred, switched = _verified(model, sets_m[0], P_tr, sets_m[1], pred, verify,
                                       verify_margin)
            preds["gse_verified"], models["gse_verified"] = pred, model
            heading = angular_rmse(pred[:, 2], P_te[:, 2]) if P_te.shape[1] > 2 else None
            out.append(MethodResult("gse_verified", heading_rmse=heading,
                                    params={**params, "verify": verify,
                                            "verify_margin": verify_margin,
                                            "switched": int(switched.sum())},
                                    fit_s=time.perf_counter() - t0,
                                    **position_errors(pred, P_te)))
    return out, preds, models


def _verified(model: GSERegressor, W_tr: Array, P_tr: Array, W_te: Array, theta0: Array,
              n_candidates: int, margin: float) -> tuple[Array, Array]:
    """psi* of the test rows ``theta0`` verified against ``n_candidates`` retrieved training
    poses (:func:`~localization.gse.inverse.verify_poses`; the whitener of the training
    residuals about Phi*) and the rows switched."""
    L = residual_whitener(model, W_tr, P_tr)
    return verify_poses(model, W_te, theta0, L, n_candidates, margin)


def _fit_method(name: str, W_tr: Array, P_tr: Array, q: int, periodic: tuple[int, ...],
                cv: int, seed: int, gse_grid: dict[str, list[Any]] | None
                ) -> tuple[Any, dict[str, Any], list[dict[str, Any]]]:
    """One method fitted on the training split, hyper-parameters by CV there."""
    if name == "gse":
        model, params, rows = fit_gse(W_tr, P_tr, q, periodic, cv, gse_grid, seed)
        params = {**params, "agreement_tau": model.agreement_,
                  "bandwidth_factor": model.bandwidth_w_,
                  "loop_cut": model.loop_angle_ is not None}
        return model, params, rows
    if name not in ("knr", "knn"):
        raise KeyError(f"unknown method {name!r}; choose from gse, knr, knn")
    est = (KernelRegressor(periodic=periodic) if name == "knr" else
           RetrievalRegressor(n_neighbors="cv", periodic=periodic, random_state=seed))
    params, rows = grid_search(est, {"standardize": [True, False]}, W_tr, P_tr, cv,
                               columns=(0, 1), random_state=seed)
    model = est.set_params(**params).fit(W_tr, P_tr)
    params = {**params, **({"bandwidth": model.bandwidth_} if name == "knr"
                           else {"n_neighbors": model.n_neighbors_})}
    return model, params, rows
