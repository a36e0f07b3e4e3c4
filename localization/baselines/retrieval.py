"""RetrievalRegressor: kNN image retrieval (the pose of the k most similar training
features), on ``sklearn.neighbors.KNeighborsRegressor``."""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from sklearn.model_selection import KFold
from sklearn.neighbors import KNeighborsRegressor, NearestNeighbors
from sklearn.utils._param_validation import Interval, StrOptions

from localization.baselines._base import _PoseRegressorBase
from localization.geometry import Array

__all__ = ["RetrievalRegressor", "cv_neighbor_errors"]


def _neighbor_mean(dist: Array, Y: Array, weights: str) -> Array:
    """The prediction of ``KNeighborsRegressor`` from its neighbours: the mean of the rows of
    ``Y`` (q, k, p), weighted by ``1 / dist`` (q, k) for ``weights="distance"`` (a row with
    a zero distance keeps only its zero-distance neighbours, as scikit-learn does)."""
    if weights == "uniform":
        return Y.mean(axis=1)
    with np.errstate(divide="ignore"):
        inv = 1.0 / dist
    exact = np.isinf(inv)
    rows = exact.any(axis=1)
    inv[rows] = exact[rows]
    return np.einsum("qk,qkp->qp", inv, Y) / inv.sum(axis=1)[:, None]


def cv_neighbor_errors(X: Array, Y: Array, ks: Sequence[int], weights: str,
                       folds: KFold, algorithm: str = "brute") -> Array:
    """Mean squared error of k-nearest-neighbour regression for every k in ``ks``, averaged
    over the ``folds`` of (X, Y): what ``GridSearchCV`` over ``n_neighbors`` reports (as
    ``-mean_test_score``), from one neighbour query of ``max(ks)`` per fold instead of one
    per k (the k nearest are the first k of the ``max(ks)`` nearest).

    Parameters
    ----------
    X : ndarray of shape (n, n_features)
    Y : ndarray of shape (n, n_outputs)
    ks : sequence of int, each in [1, the smallest training fold]
    weights : {"distance", "uniform"}
    folds : a scikit-learn splitter

    Returns
    -------
    ndarray of shape (len(ks),)
    """
    errors = np.zeros(len(ks))
    for train, test in folds.split(X):
        index = NearestNeighbors(n_neighbors=max(ks), algorithm=algorithm).fit(X[train])
        dist, ind = index.kneighbors(X[test])
        Y_nb = Y[train][ind]  # (q, max(ks), p), gathered once for every k
        for j, k in enumerate(ks):
            pred = _neighbor_mean(dist[:, :k], Y_nb[:, :k], weights)
            errors[j] += np.mean((pred - Y[test]) ** 2)
    return errors / folds.get_n_splits()


class RetrievalRegressor(_PoseRegressorBase):
    """kNN retrieval: the (weighted) mean pose of the k nearest training features.

    A thin wrapper of ``sklearn.neighbors.KNeighborsRegressor`` that adds periodic
    output columns, input standardisation, and optional choice of k by CV.

    Parameters
    ----------
    n_neighbors : int or "cv", default=1
        Number of neighbours, or ``"cv"`` to choose it from ``k_grid`` by
        ``cv``-fold shuffled KFold cross-validation (mean squared error of the encoded
        outputs, as ``GridSearchCV`` scores it; one neighbour query per fold serves every
        k: :func:`cv_neighbor_errors`) on the training set.
    weights : {"distance", "uniform"}, default="distance"
        Passed to ``KNeighborsRegressor`` (a query equal to a training point
        returns that point's target).
    periodic : sequence of int, default=()
        Angle columns of Y, averaged as (cos, sin) and returned via atan2.
    standardize : bool, default=True
        Zero-mean / unit-variance input features before the neighbour search.
    k_grid : sequence of int, default=(1, 2, 3, 4, 6, 8, 12, 16, 24, 32)
        Candidates for ``n_neighbors="cv"`` (values >= the fold size are dropped).
    cv : int, default=5
        Number of folds for ``n_neighbors="cv"``.
    random_state : int, default=0
        Seed of the fold shuffling.
    algorithm : str, default="brute"
        Neighbour search of ``KNeighborsRegressor``; brute force (BLAS) is the fastest
        for image features (tens to thousands of dimensions, where trees do not help).

    Attributes
    ----------
    n_neighbors_ : int
    cv_scores_ : ndarray of shape (len(k_grid),) or None
        Mean CV squared error per candidate k (``n_neighbors="cv"`` only).
    knn_ : KNeighborsRegressor
    mean_, scale_ : ndarray of shape (n_features,)
    X_train_, Y_train_ : training arrays
    """

    _fitted_scalars = ("n_neighbors_", "cv_k_", "cv_scores_")
    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_neighbors": [Interval(Integral, 1, None, closed="left"), StrOptions({"cv"})],
        "weights": [StrOptions({"distance", "uniform"})],
        "periodic": ["array-like"],
        "standardize": ["boolean"],
        "k_grid": ["array-like"],
        "cv": [Interval(Integral, 2, None, closed="left")],
        "random_state": ["random_state"],
        "algorithm": [StrOptions({"auto", "ball_tree", "kd_tree", "brute"})],
    }

    def __init__(self, n_neighbors: int | str = 1, weights: str = "distance",
                 periodic: Sequence[int] = (), standardize: bool = True,
                 k_grid: Sequence[int] = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32), cv: int = 5,
                 random_state: int = 0, algorithm: str = "brute") -> None:
        self.n_neighbors = n_neighbors
        self.weights = weights
        self.periodic = periodic
        self.standardize = standardize
        self.k_grid = k_grid
        self.cv = cv
        self.random_state = random_state
        self.algorithm = algorithm

    def fit(self, X: ArrayLike, Y: ArrayLike) -> RetrievalRegressor:
        """Index the training features.

        Parameters
        ----------
        X : array_like of shape (n, n_features)
        Y : array_like of shape (n, n_outputs) or (n,)

        Returns
        -------
        self
        """
        self._validate_params()
        X, Y = self._validate_fit(X, Y)
        if self.weights not in ("distance", "uniform"):
            raise ValueError(f"weights must be 'distance' or 'uniform', got {self.weights!r}")
        n = X.shape[0]
        self.cv_k_, self.cv_scores_ = None, None
        if self.n_neighbors == "cv":
            Xs, E = self._prepare(X, Y)
            n_fit = n - int(np.ceil(n / self.cv))
            ks = sorted({int(k) for k in self.k_grid if 1 <= int(k) <= n_fit})
            if not ks:
                raise ValueError(f"no k in k_grid={tuple(self.k_grid)} fits {n_fit} samples "
                                 "per fold")
            errors = cv_neighbor_errors(Xs, E, ks, self.weights, KFold(
                self.cv, shuffle=True, random_state=self.random_state), self.algorithm)
            k = ks[int(np.argmin(errors))]
            self.cv_k_ = ks
            self.cv_scores_ = errors.tolist()
        elif isinstance(self.n_neighbors, (int, np.integer)) and not isinstance(self.n_neighbors,
                                                                                bool):
            k = int(self.n_neighbors)
            if not 1 <= k <= n:
                raise ValueError(f"n_neighbors={k} must be in [1, n_samples={n}]")
        else:
            raise ValueError(f"n_neighbors must be a positive int or 'cv', got "
                             f"{self.n_neighbors!r}")
        self.n_neighbors_ = k
        self._set_data(X, Y)
        return self

    def _prepare(self, X: Array, Y: Array) -> tuple[Array, Array]:
        if self.standardize:
            self.mean_ = X.mean(axis=0)
            sd = X.std(axis=0)
            self.scale_ = np.where(sd > 0, sd, 1.0)
        else:
            self.mean_, self.scale_ = np.zeros(X.shape[1]), np.ones(X.shape[1])
        return (X - self.mean_) / self.scale_, self._encode(Y)

    def _set_data(self, X: Array, Y: Array) -> None:
        Xs, E = self._prepare(X, Y)
        self.X_train_, self.Y_train_ = X, Y
        self.knn_ = KNeighborsRegressor(n_neighbors=self.n_neighbors_, weights=self.weights,
                                        algorithm=self.algorithm).fit(Xs, E)

    def _restore(self, X: Array, Y: Array, fitted: dict[str, Any]) -> None:
        X, Y = self._validate_fit(X, Y)
        self.n_neighbors_ = int(fitted["n_neighbors_"])
        self.cv_k_, self.cv_scores_ = fitted["cv_k_"], fitted["cv_scores_"]
        self._set_data(X, Y)

    def predict(self, X: ArrayLike) -> Array:
        """Pose of the retrieved training images.

        Parameters
        ----------
        X : array_like of shape (n_queries, n_features)

        Returns
        -------
        ndarray of shape (n_queries, n_outputs) (or (n_queries,) if fitted with 1-D Y)
            Periodic columns in (-pi, pi].
        """
        X = self._validate_predict(X)
        E = self.knn_.predict((X - self.mean_) / self.scale_)
        return self._decode(np.asarray(E, dtype=np.float64).reshape(len(X), -1))
