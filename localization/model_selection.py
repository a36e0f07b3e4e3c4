"""Hyper-parameter choice for the pose regressors by cross-validation on training data.

``grid_search`` wraps :class:`sklearn.model_selection.GridSearchCV` with a pose scorer
(minus the RRMSE of chosen columns, angle columns wrapped) and seeded shuffled K-fold
splits; a fit or prediction that raises ``ValueError`` (e.g. a disconnected neighbourhood
graph for a small ``n_neighbors``, or queries outside the training domain) scores
``-inf`` instead of aborting the search. Use it on the *training* split only: the test
split must never inform a hyper-parameter.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import FitFailedWarning
from sklearn.model_selection import GridSearchCV, KFold

from localization.geometry import Array
from localization.gse.regressor import GSERegressor
from localization.metrics import rrmse

__all__ = ["PoseScorer", "grid_search", "select_n_neighbors"]


class PoseScorer:
    """Scorer ``(estimator, X, Y) -> -RRMSE`` over ``columns``; ``-inf`` if predict fails or
    returns non-finite values (sklearn maximises scores)."""

    def __init__(self, columns: Sequence[int] | None = None,
                 periodic: Sequence[int] = ()) -> None:
        self.columns = None if columns is None else tuple(columns)
        self.periodic = tuple(periodic)

    def __call__(self, estimator: Any, X: Array, Y: Array) -> float:
        try:
            pred = estimator.predict(X)
        except ValueError:
            return -np.inf
        if not np.all(np.isfinite(pred)):
            return -np.inf
        return -rrmse(pred, Y, columns=self.columns, periodic=self.periodic)


def grid_search(estimator: BaseEstimator, param_grid: Mapping[str, Sequence[Any]],
                X: Array, Y: Array, cv: int = 3, columns: Sequence[int] | None = None,
                periodic: Sequence[int] = (), random_state: int = 0
                ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Best parameters of ``estimator`` on ``param_grid`` by ``cv``-fold CV of pose RRMSE.

    Parameters
    ----------
    estimator : a regressor with ``fit(X, Y)`` / ``predict(X)``
    param_grid : dict of parameter name -> candidate values
    X : ndarray of shape (n, m)
        Training features.
    Y : ndarray of shape (n, d)
        Training poses.
    cv : int, default=3
    columns, periodic : passed to :func:`localization.metrics.rrmse`
        (default columns: every non-periodic one).
    random_state : int, default=0
        Seed of the fold shuffling.

    Returns
    -------
    best_params : dict
    results : list of dict
        One row per candidate: its parameters and ``rrmse`` (mean over folds; ``inf`` if
        any fold failed).
    """
    search = GridSearchCV(estimator, dict(param_grid), scoring=PoseScorer(columns, periodic),
                          cv=KFold(cv, shuffle=True, random_state=random_state),
                          error_score=-np.inf, refit=False, n_jobs=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitFailedWarning)  # failures are scored -inf
        warnings.simplefilter("ignore", UserWarning)  # "one or more test scores are non-finite"
        search.fit(X, Y)
    res = search.cv_results_
    rows = [{**p, "rrmse": float(-s)} for p, s in zip(res["params"], res["mean_test_score"])]
    if not np.isfinite(res["mean_test_score"]).any():
        raise ValueError(f"every candidate of {dict(param_grid)} failed in cross-validation")
    return dict(search.best_params_), rows


def select_n_neighbors(W: Array, Theta: Array, grid: tuple[int, ...] = (10, 15, 20, 30),
                       cv: int = 3, random_state: int = 0, **params: object
                       ) -> tuple[int, dict[int, float]]:
    """Choose ``GSERegressor(n_neighbors)`` by K-fold cross-validation of psi* (pose RRMSE
    over all columns, angles wrapped).

    Returns the best k and the mean validation RRMSE for every k in ``grid``
    (``inf`` where a fit failed, e.g. a disconnected graph for small k).
    """

    periodic = tuple(params.get("periodic", ()))  # type: ignore[arg-type]
    columns = range(np.shape(Theta)[1])
    best, rows = grid_search(GSERegressor(**params), {"n_neighbors": list(grid)},  # type: ignore[arg-type]
                             W, Theta, cv, columns, periodic, random_state)
    return int(best["n_neighbors"]), {int(r["n_neighbors"]): r["rrmse"] for r in rows}
