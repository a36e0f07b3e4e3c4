"""Baseline regressors features -> pose: kernel regression (KNR) and kNN retrieval.

``KernelRegressor`` is the seed paper's KNR baseline (section V, Table II):
Nadaraya-Watson with a Gaussian kernel and ONE global bandwidth for all output
coordinates, chosen by leave-one-out cross-validation. ``RetrievalRegressor``
is image retrieval: the pose of the k most similar training images
(``sklearn.neighbors.KNeighborsRegressor``).

Both follow scikit-learn conventions (hyper-parameters in ``__init__``, ``fit``
returns ``self``, fitted attributes end in ``_``, ``NotFittedError`` before
fit) and treat the output columns listed in ``periodic`` as angles: they are
averaged as (cos, sin) and returned through atan2, wrapped to (-pi, pi].
``save(path)`` / ``Class.load(path)`` store the training data and settings in an
``.npz`` (``allow_pickle=False``, settings as a JSON string).
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Sequence
from numbers import Integral, Real
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.metrics.pairwise import euclidean_distances
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.neighbors import KNeighborsRegressor, NearestNeighbors
from sklearn.utils import Tags
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from localization.geometry import Array, wrap_angle
from localization.gse.validation import validate_X, validate_y

__all__ = ["KernelRegressor", "RetrievalRegressor"]

#: KernelRegressor with ``n_neighbors=None`` uses all training points (dense n x n
#: distances) up to this many training samples, and the kNN-truncated kernel above it.
DENSE_LIMIT = 3000
#: Neighbours kept by the kNN-truncated kernel when ``n_neighbors=None`` and n > DENSE_LIMIT.
AUTO_NEIGHBORS = 128
_CHUNK = 2_000_000  # elements per distance block


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (tuple, list)):
        return [_jsonable(x) for x in v]
    return v


class _PoseRegressorBase(RegressorMixin, BaseEstimator):
    """Shared input checks, periodic output encoding and npz persistence."""

    _fitted_scalars: tuple[str, ...] = ()

    def __sklearn_tags__(self) -> Tags:
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        return tags

    # -- validation / encoding ------------------------------------------------------
    def _validate_fit(self, X: ArrayLike, Y: ArrayLike) -> tuple[Array, Array]:
        X = validate_X(self, X, "X", reset=True, ensure_min_samples=2)
        Y, self.y_1d_ = validate_y(self, Y, len(X), "Y", "X")
        d = Y.shape[1]
        per = [int(p) for p in self.periodic]
        if any(not 0 <= p < d for p in per) or len(set(per)) != len(per):
            raise ValueError(f"periodic={tuple(self.periodic)} invalid for Y with {d} columns")
        self.periodic_ = tuple(sorted(per))
        self.n_outputs_ = d
        return X, Y

    def _validate_predict(self, X: ArrayLike) -> Array:
        check_is_fitted(self, "X_train_")
        return validate_X(self, X, "X", reset=False)

    def _encode(self, Y: Array) -> Array:
        """(n, d) -> (n, d + len(periodic)): angle columns become cos, sin (appended)."""
        lin = [c for c in range(Y.shape[1]) if c not in self.periodic_]
        parts = [Y[:, lin]] + [np.column_stack([np.cos(Y[:, c]), np.sin(Y[:, c])])
                               for c in self.periodic_]
        return np.column_stack(parts)

    def _decode(self, E: Array) -> Array:
        d = self.n_outputs_
        lin = [c for c in range(d) if c not in self.periodic_]
        Y = np.empty((E.shape[0], d))
        Y[:, lin] = E[:, : len(lin)]
        for j, c in enumerate(self.periodic_):
            cs = E[:, len(lin) + 2 * j: len(lin) + 2 * j + 2]
            Y[:, c] = wrap_angle(np.arctan2(cs[:, 1], cs[:, 0]))
        return Y[:, 0] if self.y_1d_ else Y

    # -- persistence ---------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write training data and settings to ``path`` (npz format, exactly that name).

        Arrays ``X_train``, ``Y_train`` and ``settings`` (a JSON string with the
        constructor parameters and fitted scalars); readable with ``allow_pickle=False``.
        """
        check_is_fitted(self, "X_train_")
        params = self.get_params()
        params = {k: _jsonable(v) for k, v in params.items()}
        fitted = {k: _jsonable(getattr(self, k)) for k in self._fitted_scalars}
        settings = {"class": type(self).__name__, "params": params, "fitted": fitted,
                    "y_1d": bool(self.y_1d_)}
        with open(path, "wb") as fh:  # a file handle: numpy must not append ".npz"
            np.savez(fh, X_train=self.X_train_, Y_train=self.Y_train_,
                     settings=np.array(json.dumps(settings)))

    @classmethod
    def load(cls, path: str | os.PathLike) -> _PoseRegressorBase:
        """Rebuild a fitted model written by :meth:`save`."""
        with np.load(path, allow_pickle=False) as f:
            settings = json.loads(str(f["settings"]))
            X, Y = f["X_train"], f["Y_train"]
        if settings.get("class") != cls.__name__:
            raise ValueError(f"{path} holds a {settings.get('class')}, not a {cls.__name__}")
        params = settings["params"]
        for key in ("periodic", "k_grid"):
            if key in params:
                params[key] = tuple(params[key])
        model = cls(**params)
        model._restore(X, Y[:, 0] if settings["y_1d"] else Y, settings["fitted"])
        return model

    def _restore(self, X: Array, Y: Array, fitted: dict[str, Any]) -> None:
        raise NotImplementedError


class KernelRegressor(_PoseRegressorBase):
    """Nadaraya-Watson regression with one global Gaussian bandwidth (the paper's KNR).

    ``f(x) = sum_i K(x, x_i) y_i / sum_i K(x, x_i)``, ``K = exp(-|x - x_i|^2 / (2 h^2))``,
    computed with max-shifted log-weights so that a query far from all data gets
    the value of its nearest neighbours instead of 0/0.

    Parameters
    ----------
    bandwidth : "loo" or float, default="loo"
        ``"loo"``: choose ``h`` on ``bandwidth_grid`` by leave-one-out CV, minimising
        the mean over samples of the squared output error summed over all output
        coordinates (angles enter as (cos, sin), i.e. chord length ~ radians).
        A float: use it as is. ``h`` is in the units of the (standardised) inputs.
    bandwidth_grid : array_like of shape (n_grid,), optional
        Candidate bandwidths. Default: 40 log-spaced values from 0.25 x the median
        nearest-neighbour distance to the median pairwise distance (dense) or
        2 x the median k-th neighbour distance (kNN-truncated).
    n_neighbors : int, optional
        Truncate the kernel to the ``n_neighbors`` nearest training points
        (sparse, for large n). ``None``: all training points if n <= DENSE_LIMIT
        (3000), else the AUTO_NEIGHBORS (128) nearest. The value used is ``n_neighbors_``.
    periodic : sequence of int, default=()
        Angle columns of Y (e.g. ``(2,)`` for ``[x, y, yaw]``).
    standardize : bool, default=True
        Scale every input feature to zero mean and unit variance before computing
        distances (the paper used raw pixel features with no scaling; pass
        ``standardize=False`` to reproduce that).

    Attributes
    ----------
    bandwidth_ : float
        The bandwidth used.
    bandwidth_grid_ : ndarray of shape (n_grid,) or None
    loo_errors_ : ndarray of shape (n_grid,) or None
        LOO mean squared error per grid bandwidth (None if ``bandwidth`` is a float).
    n_neighbors_ : int or None
        Kernel truncation actually used (None: dense, all training points).
    mean_, scale_ : ndarray of shape (n_features,)
        Input standardisation (zeros / ones when ``standardize=False``).
    X_train_ : ndarray of shape (n, n_features)
    Y_train_ : ndarray of shape (n, n_outputs)
    """

    _fitted_scalars = ("bandwidth_", "n_neighbors_", "bandwidth_grid_", "loo_errors_")
    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "bandwidth": [StrOptions({"loo"}), Interval(Real, 0, None, closed="neither")],
        "bandwidth_grid": ["array-like", None],
        "n_neighbors": [Interval(Integral, 1, None, closed="left"), None],
        "periodic": ["array-like"],
        "standardize": ["boolean"],
    }

    def __init__(self, bandwidth: str | float = "loo", bandwidth_grid: ArrayLike | None = None,
                 n_neighbors: int | None = None, periodic: Sequence[int] = (),
                 standardize: bool = True) -> None:
        self.bandwidth = bandwidth
        self.bandwidth_grid = bandwidth_grid
        self.n_neighbors = n_neighbors
        self.periodic = periodic
        self.standardize = standardize

    # -- fitting -------------------------------------------------------------------
    def fit(self, X: ArrayLike, Y: ArrayLike) -> KernelRegressor:
        """Store the sample and choose the bandwidth.

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
        if isinstance(self.bandwidth, str):
            if self.bandwidth != "loo":
                raise ValueError(f"bandwidth must be 'loo' or a positive float, got "
                                 f"{self.bandwidth!r}")
        elif not (np.isfinite(self.bandwidth) and self.bandwidth > 0):
            raise ValueError(f"bandwidth must be 'loo' or a positive float, got {self.bandwidth!r}")
        n = X.shape[0]
        if self.n_neighbors is None:
            k = None if n <= DENSE_LIMIT else AUTO_NEIGHBORS
        else:
            if int(self.n_neighbors) != self.n_neighbors or self.n_neighbors < 1:
                raise ValueError(f"n_neighbors must be a positive int, got {self.n_neighbors!r}")
            k = int(self.n_neighbors)
        if k is not None and k >= n:
            k = None  # truncation to >= all points is the dense kernel
        self.n_neighbors_ = k
        self._set_data(X, Y)
        if self.bandwidth == "loo":
            self._choose_bandwidth()
        else:
            self.bandwidth_ = float(self.bandwidth)
            self.bandwidth_grid_, self.loo_errors_ = None, None
        return self

    def _set_data(self, X: Array, Y: Array) -> None:
        self.X_train_, self.Y_train_ = X, Y
        if self.standardize:
            self.mean_ = X.mean(axis=0)
            sd = X.std(axis=0)
            self.scale_ = np.where(sd > 0, sd, 1.0)
        else:
            self.mean_, self.scale_ = np.zeros(X.shape[1]), np.ones(X.shape[1])
        self._Xs = (X - self.mean_) / self.scale_
        self._E = self._encode(Y)
        self._nn = None
        if self.n_neighbors_ is not None:
            self._nn = NearestNeighbors(n_neighbors=self.n_neighbors_,
                                        algorithm="brute").fit(self._Xs)

    def _restore(self, X: Array, Y: Array, fitted: dict[str, Any]) -> None:
        X, Y = self._validate_fit(X, Y)
        self.n_neighbors_ = fitted["n_neighbors_"]
        self._set_data(X, Y)
        self.bandwidth_ = float(fitted["bandwidth_"])
        g, e = fitted["bandwidth_grid_"], fitted["loo_errors_"]
        self.bandwidth_grid_ = None if g is None else np.asarray(g, dtype=np.float64)
        self.loo_errors_ = None if e is None else np.asarray(e, dtype=np.float64)

    def _loo_blocks(self):
        """Yield (rows, squared distances to the other points, their indices or None)."""
        n = self._Xs.shape[0]
        if self.n_neighbors_ is None:
            step = max(1, _CHUNK // n)
            for i0 in range(0, n, step):
                rows = np.arange(i0, min(n, i0 + step))
                D2 = np.maximum(euclidean_distances(self._Xs[rows], self._Xs, squared=True), 0)
                D2[np.arange(len(rows)), rows] = np.inf  # leave self out
                yield rows, D2, None
        else:
            dist, idx = self._nn.kneighbors()  # X=None: a point is not its own neighbour
            yield np.arange(n), dist**2, idx

    def _choose_bandwidth(self) -> None:
        blocks = list(self._loo_blocks())  # dense: n^2 <= DENSE_LIMIT^2; kNN: n x k
        if self.bandwidth_grid is not None:
            grid = np.asarray(self.bandwidth_grid, dtype=np.float64).ravel()
            if grid.size == 0 or not np.all(np.isfinite(grid)) or np.any(grid <= 0):
                raise ValueError("bandwidth_grid must be a non-empty array of positive floats")
            grid = np.unique(grid)
        else:
            grid = self._default_grid(blocks)
        errs = np.zeros(grid.size)
        for rows, D2, idx in blocks:
            for g, h in enumerate(grid):
                pred = self._nw(D2, idx, h)
                errs[g] += np.sum((pred - self._E[rows]) ** 2)
        errs /= self._Xs.shape[0]
        best = int(np.argmin(errs))
        if grid.size > 1 and best in (0, grid.size - 1):
            warnings.warn(f"LOO bandwidth {grid[best]:.3g} is at the edge of the grid "
                          f"[{grid[0]:.3g}, {grid[-1]:.3g}]; widen bandwidth_grid", stacklevel=3)
        self.bandwidth_grid_, self.loo_errors_, self.bandwidth_ = grid, errs, float(grid[best])

    def _default_grid(self, blocks) -> Array:
        if self.n_neighbors_ is None:  # dense
            nn = np.concatenate([np.sqrt(D2.min(axis=1)) for _, D2, _ in blocks])
            rng = np.random.default_rng(0)
            sub = self._Xs[rng.choice(len(self._Xs), min(1000, len(self._Xs)), replace=False)]
            hi = float(np.median(euclidean_distances(sub, sub)[np.triu_indices(len(sub), 1)]))
        else:
            dist = np.sqrt(blocks[0][1])
            nn, hi = dist[:, 0], 2.0 * float(np.median(dist[:, -1]))
        lo = 0.25 * float(np.median(nn))
        if not lo > 0:
            lo = max(hi * 1e-3, 1e-12)
        hi = max(hi, 10 * lo)
        return np.geomspace(lo, hi, 40)

    def _nw(self, D2: Array, idx: Array | None, h: float) -> Array:
        """Kernel average of the encoded outputs; D2 (c, n) dense or (c, k) with idx."""
        L = -D2 / (2.0 * h * h)
        L -= L.max(axis=1, keepdims=True)  # max weight is exactly 1: never 0/0
        Wt = np.exp(L)
        Wt /= Wt.sum(axis=1, keepdims=True)
        if idx is None:
            return Wt @ self._E
        return np.einsum("ck,ckd->cd", Wt, self._E[idx])

    # -- prediction ----------------------------------------------------------------
    def predict(self, X: ArrayLike) -> Array:
        """Kernel-weighted average of the training outputs.

        Parameters
        ----------
        X : array_like of shape (n_queries, n_features)

        Returns
        -------
        ndarray of shape (n_queries, n_outputs) (or (n_queries,) if fitted with 1-D Y)
            Periodic columns in (-pi, pi].
        """
        X = self._validate_predict(X)
        Xs = (X - self.mean_) / self.scale_
        n = self._Xs.shape[0]
        if self.n_neighbors_ is None:
            step = max(1, _CHUNK // n)
            out = [self._nw(np.maximum(euclidean_distances(Xs[i:i + step], self._Xs,
                                                           squared=True), 0), None, self.bandwidth_)
                   for i in range(0, len(Xs), step)]
            E = np.concatenate(out, axis=0)
        else:
            dist, idx = self._nn.kneighbors(Xs)
            E = self._nw(dist**2, idx, self.bandwidth_)
        return self._decode(E)


class RetrievalRegressor(_PoseRegressorBase):
    """kNN retrieval: the (weighted) mean pose of the k nearest training features.

    A thin wrapper of ``sklearn.neighbors.KNeighborsRegressor`` that adds periodic
    output columns, input standardisation, and optional choice of k by CV.

    Parameters
    ----------
    n_neighbors : int or "cv", default=1
        Number of neighbours, or ``"cv"`` to choose it from ``k_grid`` by
        ``GridSearchCV`` (``cv``-fold shuffled KFold, mean squared error of the
        encoded outputs) on the training set.
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
            search = GridSearchCV(KNeighborsRegressor(weights=self.weights,
                                                      algorithm=self.algorithm),
                                  {"n_neighbors": ks}, scoring="neg_mean_squared_error",
                                  cv=KFold(self.cv, shuffle=True, random_state=self.random_state))
            search.fit(Xs, E)
            k = int(search.best_params_["n_neighbors"])
            self.cv_k_ = ks
            self.cv_scores_ = (-search.cv_results_["mean_test_score"]).tolist()
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
