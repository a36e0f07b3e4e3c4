"""Regression on an unknown input manifold with GSE (docs/method.md §8).

GSE is fitted on ``Z = (standardised w, scaled theta)``; the representation maps
``r(w)`` and ``R(theta)`` are extended off the sample by Jacobian Regression and
composed with the recovery map: ``psi*(w) = g_v(r*(w))``, ``Phi*(theta) = g_u(R*(theta))``.

A periodic pose column (yaw) enters Z as a (cos, sin) pair of radius
``theta_scale`` (so Z-space neighbourhoods see the true geometry), and the GSE
graph is cut open at yaw = +-pi: a closed loop cannot be embedded by the
least-squares step of docs/method.md §6 (see §10). The same holds for a closed loop
traced by the positions (a robot driving around a block, as in the paper's
experiment): ``loop_cut="auto"`` detects it (:func:`~localization.gse.graph.loop_coordinate`)
and cuts it at one place. Every kernel average keeps only the neighbours on the
nearest neighbour's side of every cut.
"""

from __future__ import annotations

from numbers import Integral, Real
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import Tags
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from localization.geometry import wrap_angle
from localization.gse.alignment import _KERNELS
from localization.gse.embedding import GrassmannStiefelEigenmaps
from localization.gse.estimator_checks import regressor_expected_failed_checks
from localization.gse.first_order import FIRST_ORDER, FORWARD_NEIGHBORS, forward_gls_jacobians
from localization.gse.graph import (
    Array,
    cuts_keep_connected,
    local_pca,
    loop_coordinate,
    pinv_blocks,
)
from localization.gse.incremental import add_regression_samples
from localization.gse.io import load_regressor, save_regressor
from localization.gse.jacobian_regression import (
    AGREEMENT_GRID,
    BANDWIDTH_GRID,
    LooChunk,
    loo_bandwidth_chunked,
)
from localization.gse.neighbors import ALGORITHMS, HNSWIndex, knn_graph_any, use_approximate
from localization.gse.pose_block import PoseBlockMixin
from localization.gse.queries import KDTREE_MAX_DIM, GSEQueryMixin
from localization.gse.validation import validate_X, validate_y

__all__ = ["GSERegressor", "pinv_blocks"]

def _broadcast_scale(theta_scale: object, d: int) -> Array:
    """``theta_scale`` (a number or d numbers) as an array of shape (d,)."""
    scale = np.asarray(theta_scale, dtype=float)
    if scale.ndim > 1 or scale.size not in (1, d):
        raise ValueError(f"theta_scale must be 'auto', a number or {d} numbers (one per pose "
                         f"column), got shape {scale.shape}")
    return np.broadcast_to(scale.ravel() if scale.ndim else scale, (d,)).copy()


class GSERegressor(PoseBlockMixin, GSEQueryMixin, RegressorMixin, BaseEstimator):
    """GSE regression between features w (n, m) and poses theta (n, d).

    Parameters
    ----------
    n_components : int or None, default=None
        Intrinsic dimension q; None = number of Theta columns.
    n_neighbors : int, default=20
        Neighbourhood size of GSE and of every kernel average.
    periodic : tuple of int, default=()
        Angle columns of Theta (radians); at most one.
    theta_scale : "auto", float or array of shape (d,), default="auto"
        Factor lambda applied to theta in Z; "auto" = median of |dw| / |dtheta| over
        feature-space neighbours, so pose and feature variation in a neighbourhood
        are comparable (and a disconnected feature sample is not bridged by poses).
    bandwidth : "auto" or float, default="auto"
        GSE heat-kernel bandwidth (see :class:`GrassmannStiefelEigenmaps`).
    grassmann_kernel : str, default="binet_cauchy"
    project_features : bool, default=False
        Use ``G_r = G_u^- pi_W`` with pi_W from local PCA of the w-sample
        (``first_order="frames"`` only).
    ridge : float, default=0.0
        Tikhonov term for ``G_v^{-1}``.
    bandwidth_grid : tuple of float
        Relative grid for the leave-one-out JR bandwidths.
    out_of_domain : {"raise", "nan", "ignore"}, default="raise"
        Queries whose kernel sum is negligible: raise, NaN, or the estimate anyway.
    random_state : int, default=0
    theta_scale_factor : float, default=2.0
        With theta_scale="auto": lambda_c = factor x median |dw/dtheta_c| (pose columns
        then weigh a bit more than features, which keeps cond(G_v) near 1).
    jr_neighbors : int or None, default=None
        Neighbours of the two Jacobian regressions (None: n_neighbors).
    kernel_grassmann : bool, default=False
        Multiply K_W by the Binet-Cauchy factor between the local PCA tangent of the
        w-sample at the query and Span(G_u) at the sample (docs/method.md §8.2). The factor is not
        differentiated: embed_jacobian then ignores its (small) derivative.
    loop_cut : {"auto", "none"}, default="auto"
        "auto": if the linear (position) columns of Theta trace a closed loop, cut it
        open at one place (angle in ``loop_angle_``), like the yaw cut; unless the
        yaw cut already opens it (a heading that turns once along the loop: the pose
        graph would fall apart with both cuts). Needed when
        ``n_components`` is smaller than the loop's embedding needs (a closed route
        with n_components=1).
    adaptive_bandwidth : bool, default=False
        Sample-point adaptive kernels of r* and R*: training point j gets the bandwidth
        ``bandwidth_w_ x w_radius_[j]`` (its distance to its jr_neighbors-th
        feature-space neighbour; ``bandwidth_theta_ x theta_radius_[j]`` in pose
        space), so sparsely sampled stretches (a robot turning: images change fast;
        gaps along a route) keep kernel support. The bandwidths are then LOO factors.
    agreement : None, "auto" or float, default=None
        Robust r*: weight each neighbour also by the agreement of its first-order
        prediction ``y_j + G_r (w - w_j)`` with the densest group of predictions
        (:func:`~localization.gse.jacobian_regression.agreement_factor`), with scale
        ``tau = agreement x`` the median y-distance to the jr_neighbors-th neighbour.
        Look-alike places among the feature-space neighbours then drop out. "auto":
        choose the factor (or none) with the bandwidth by leave-one-out.
    algorithm : {"auto", "exact", "approximate"}, default="auto"
        Neighbour search and solvers: "exact" (scikit-learn kNN, brute-force / KD-tree
        queries, the eigensolvers of :class:`GrassmannStiefelEigenmaps`); "approximate",
        the scalable path (faiss HNSW neighbours re-ranked by exact distance, AMG-
        preconditioned LOBPCG and CG; docs/method.md §17); "auto": "approximate" from
        :data:`~localization.gse.neighbors.APPROXIMATE_MIN_N` samples on.
    first_order : {"frames", "forward"}, default="frames"
        The first-order terms G_j of r*: the pseudo-inverse of the feature block of GSE's
        recovery Jacobian ("frames"), or the generalised least-squares inverse of the
        forward model w(theta) fitted on each sample's pose-space neighbours, in the metric
        of its residual covariance ("forward", :mod:`~localization.gse.first_order`: less
        shrinkage of psi* across a lane map, docs/method.md §8.5).
    forward_ridge : float, default=0.0
        first_order="forward" only: the inverse damps each sample's pose directions of least
        feature information by ``forward_ridge`` x its mean information
        (:func:`~localization.gse.first_order.gls_left_inverse`): less gain, so less
        feature noise passed on, where the features barely see the pose.

    Attributes
    ----------
    gse_ : GrassmannStiefelEigenmaps
    embedding_ : ndarray of shape (n, q)
    theta_scale_ : ndarray of shape (d,)
    bandwidth_w_, bandwidth_theta_ : float
        LOO bandwidths of r* (standardised w units, or a factor of ``w_radius_`` with
        adaptive_bandwidth) and R* (scaled theta units).
    agreement_ : float or None
        tau of the agreement factor of r* (None: off).
    w_radius_, theta_radius_ : ndarray of shape (n,)
        Distance of each sample to its jr_neighbors-th neighbour in feature space
        (standardised) and in pose space (scaled).
    pose_condition_ : ndarray of shape (n,)
        cond(G_v) at the samples.
    feature_precision_ : ndarray of shape (m, m) or None
        The inverse residual covariance of the forward model (first_order="forward"; None
        with "frames"), in standardised feature units.
    loop_angle_ : ndarray of shape (n,) or None
        Angle along the detected position loop (None: no loop, or loop_cut="none").
    cut_ : ndarray of shape (n, c) or None
        All cut coordinates (periodic columns, then the loop angle).
    n_features_in_ : int
        Number of feature columns m.
    y_1d_ : bool
        Whether the poses were given as a 1-D array (:meth:`predict` then returns one too).
    algorithm_ : str
        The path that ran: "exact" or "approximate".
    """

    _parameter_constraints: ClassVar[dict[str, list[Any]]] = {
        "n_components": [Interval(Integral, 1, None, closed="left"), None],
        "n_neighbors": [Interval(Integral, 1, None, closed="left")],
        "periodic": ["array-like"],
        "theta_scale": [StrOptions({"auto"}), Interval(Real, 0, None, closed="neither"),
                        "array-like"],
        "bandwidth": [StrOptions({"auto"}), Interval(Real, 0, None, closed="neither")],
        "grassmann_kernel": [StrOptions(set(_KERNELS))],
        "project_features": ["boolean"],
        "ridge": [Interval(Real, 0, None, closed="left")],
        "bandwidth_grid": ["array-like"],
        "out_of_domain": [StrOptions({"raise", "nan", "ignore"})],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "theta_scale_factor": [Interval(Real, 0, None, closed="neither")],
        "jr_neighbors": [Interval(Integral, 1, None, closed="left"), None],
        "kernel_grassmann": ["boolean"],
        "loop_cut": [StrOptions({"auto", "none"})],
        "adaptive_bandwidth": ["boolean"],
        "agreement": [None, StrOptions({"auto"}), Interval(Real, 0, None, closed="neither")],
        "algorithm": [StrOptions(set(ALGORITHMS))],
        "first_order": [StrOptions(set(FIRST_ORDER))],
        "forward_ridge": [Interval(Real, 0, None, closed="left")],
    }

    def __init__(self, n_components: int | None = None, n_neighbors: int = 20,
                 periodic: tuple[int, ...] = (), theta_scale: float | str | Array = "auto",
                 bandwidth: float | str = "auto", grassmann_kernel: str = "binet_cauchy",
                 project_features: bool = False, ridge: float = 0.0,
                 bandwidth_grid: tuple[float, ...] = BANDWIDTH_GRID,
                 out_of_domain: str = "raise", random_state: int = 0,
                 theta_scale_factor: float = 2.0, jr_neighbors: int | None = None,
                 kernel_grassmann: bool = False, loop_cut: str = "auto",
                 adaptive_bandwidth: bool = False, agreement: float | str | None = None,
                 algorithm: str = "auto", first_order: str = "frames",
                 forward_ridge: float = 0.0) -> None:
        self.n_components = n_components
        self.n_neighbors = n_neighbors
        self.periodic = periodic
        self.theta_scale = theta_scale
        self.bandwidth = bandwidth
        self.grassmann_kernel = grassmann_kernel
        self.project_features = project_features
        self.ridge = ridge
        self.bandwidth_grid = bandwidth_grid
        self.out_of_domain = out_of_domain
        self.random_state = random_state
        self.theta_scale_factor = theta_scale_factor
        self.jr_neighbors = jr_neighbors
        self.kernel_grassmann = kernel_grassmann
        self.loop_cut = loop_cut
        self.adaptive_bandwidth = adaptive_bandwidth
        self.agreement = agreement
        self.algorithm = algorithm
        self.first_order = first_order
        self.forward_ridge = forward_ridge

    # --------------------------------------------------------------------- fit
    def __sklearn_tags__(self) -> Tags:
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        # GSE assumes the features are a smooth function of the pose (a d-dimensional
        # manifold); scikit-learn's regression data set has 9 of 10 features pure noise
        tags.regressor_tags.poor_score = True
        return tags

    def _expected_failed_checks(self) -> dict[str, str]:
        """scikit-learn estimator checks that cannot apply to this instance, with the reason
        (``parametrize_with_checks(..., expected_failed_checks=...)``)."""
        return regressor_expected_failed_checks(self)

    def fit(self, W: Array, y: Array) -> GSERegressor:
        """Fit psi*, Phi* and their Jacobians on features and poses.

        Parameters
        ----------
        W : array_like of shape (n, m)
            Features, one row per sample.
        y : array_like of shape (n, d) or (n,)
            Poses Theta (angles of the ``periodic`` columns in radians); a 1-D ``y`` is
            one pose column, and :meth:`predict` then returns shape (n,).

        Returns
        -------
        self
        """
        self._validate_params()
        W = validate_X(self, W, "W", reset=True)
        Theta, self.y_1d_ = validate_y(self, y, len(W), "y", "W")
        (n, m), d = W.shape, Theta.shape[1]
        self._per = self._periodic(d)
        q = d if self.n_components is None else self.n_components
        if q > d:
            raise ValueError(f"n_components={q} must be at most the number of pose columns "
                             f"of y ({d}): the representation is a chart of the poses")
        k = self.n_neighbors
        if n <= k + 1:
            raise ValueError(f"need more samples than n_neighbors + 1: n_samples={n}, "
                             f"n_neighbors={k}")
        Theta = Theta.copy()
        for c in self._per:
            Theta[:, c] = wrap_angle(Theta[:, c])
        self.w_mean_ = W.mean(axis=0)
        self.w_scale_ = float(np.sqrt(W.var(axis=0).mean()))
        if not self.w_scale_ > 0:
            raise ValueError("W is constant: features carry no information")
        Ws = (W - self.w_mean_) / self.w_scale_
        self.theta_center_ = np.where(np.isin(np.arange(d), self._per), 0.0, Theta.mean(axis=0))
        self.algorithm_ = "approximate" if use_approximate(self.algorithm, n) else "exact"
        dist_w, ind_w, self._ws_index = knn_graph_any(Ws, k, self.algorithm_ == "approximate")
        if isinstance(self.theta_scale, str):
            self.theta_scale_ = self.theta_scale_factor * self._auto_scale(Ws, Theta, ind_w)
        else:
            self.theta_scale_ = _broadcast_scale(self.theta_scale, d)
        if not np.all(self.theta_scale_ > 0):
            raise ValueError(f"theta_scale must be positive, got {self.theta_scale_}: with "
                             "theta_scale='auto' a zero means that y column never varies "
                             "within a feature-space neighbourhood (constant, or constant per "
                             "cluster of features): drop it or pass theta_scale explicitly")
        self.theta_ = Theta
        lin = [c for c in range(d) if c not in self._per]
        self.loop_angle_ = (loop_coordinate(Theta[:, lin], k, seed=self.random_state)
                            if self.loop_cut == "auto" and lin else None)
        if self.loop_angle_ is not None and self._per and not cuts_keep_connected(
                self._lift(Theta), np.column_stack([Theta[:, self._per], self.loop_angle_]), k):
            self.loop_angle_ = None  # the heading wraps once along the loop: its cut opens it
        cuts = [Theta[:, c] for c in self._per] + (
            [self.loop_angle_] if self.loop_angle_ is not None else [])
        self.cut_ = np.column_stack(cuts) if cuts else None
        Z = np.column_stack([Ws, self._lift(Theta)])
        self.gse_ = GrassmannStiefelEigenmaps(
            q, n_neighbors=k, bandwidth=self.bandwidth, grassmann_kernel=self.grassmann_kernel,
            out_of_domain=self.out_of_domain, random_state=self.random_state,
            algorithm=self.algorithm_)
        self.gse_.fit(Z, cut=self.cut_)
        self.gse_.select_recovery_bandwidth()
        H = self.gse_.frames_
        Bq, _ = np.linalg.qr(H[:, :m, :])
        self._w_tangents = Bq
        if self.first_order == "frames":
            self.Gr_ = pinv_blocks(H[:, :m, :])
            if self.project_features:
                w = np.exp(-0.5 * (dist_w / (0.5 * np.median(dist_w[:, -1]))) ** 2)
                U = local_pca(Ws, Ws, ind_w, w, q)
                self.Gr_ = (self.Gr_ @ U) @ np.swapaxes(U, 1, 2)
        Hv = H[:, m:, :]
        self.GR_ = pinv_blocks(Hv, self.ridge) @ self._dlift(Theta)
        s = np.linalg.svd(Hv, compute_uv=False)
        self.pose_condition_ = s[:, 0] / np.maximum(s[:, -1], np.finfo(float).tiny)
        self._setup()
        self.feature_precision_ = None
        if self.first_order == "forward":  # needs GR_ and the pose tree of _setup
            self.Gr_, self.feature_precision_ = self._forward_first_order(np.arange(n))
        self._select_bandwidths(Ws, Theta, dist_w, ind_w)
        return self

    def partial_fit(self, W: Array, y: Array) -> GSERegressor:
        """Add samples to the fitted model without a refit (incremental GSE).

        A local update (docs/method.md §18, :mod:`localization.gse.incremental`): the new
        samples and the old ones whose neighbourhoods change get new tangents, frames,
        coordinates and Jacobians ``G_r``, ``G_R``; everything else is kept, in particular
        the standardisation of w, the pose scale, the cuts and the leave-one-out
        bandwidths of the fit. Deterministic (the same data give the same model).

        Parameters
        ----------
        W : array_like of shape (n_new, m)
            Features of the new samples, with the m columns of the fit.
        y : array_like of shape (n_new, d) or (n_new,)
            Their poses Theta, in the layout of the fit (``y`` as in :meth:`fit` and
            scikit-learn's ``partial_fit``).

        Returns
        -------
        self
            With ``partial_fit_rows_``: the rows whose model changed.
        """
        self._validate_params()
        check_is_fitted(self, "gse_", msg="This %(name)s instance is not fitted yet: call "
                        "'fit' before 'partial_fit' (partial_fit adds samples to a fitted "
                        "model)")
        return add_regression_samples(self, W, y)

    def _select_bandwidths(self, Ws: Array, Theta: Array, dist_w: Array, ind_w: Array) -> None:
        """Leave-one-out bandwidths (and agreement scale) of the two Jacobian regressions
        r* (features) and R* (poses)."""
        n, k = len(Ws), self.n_neighbors
        y = self.embedding_
        self.jr_neighbors_ = kj = min(self.jr_neighbors or k, n - 2)
        if kj != k:
            d2, ind_w = self._query_w(Ws, kj + 1)
            ind_w, dist_w = ind_w[:, 1:], np.sqrt(d2[:, 1:])
        mask = self._mask(ind_w)
        grid = np.asarray(self.bandwidth_grid)
        self._pca_bw = 0.5 * float(np.median(dist_w[:, -1]))
        self.w_radius_ = dist_w[:, -1].copy()
        y_radius = float(np.median(cKDTree(y).query(y, k=kj + 1)[0][:, -1]))
        taus = {"auto": (None, *AGREEMENT_GRID), None: (None,)}.get(self.agreement,  # type: ignore[call-overload]
                                                                    (self.agreement,))
        best = (np.inf, 0.0, None)
        ad = self.adaptive_bandwidth
        for a in taus:
            tau = None if a is None else float(a) * y_radius

            def chunk_w(sl: slice) -> LooChunk:
                iw = ind_w[sl]
                return (Ws[sl, None, :] - Ws[iw], y[iw], self.Gr_[iw], y[sl],
                        None if mask is None else mask[sl], self._w_factor(Ws[sl], iw),
                        self.w_radius_[iw] if ad else None)

            bw, mse = loo_bandwidth_chunked(
                n, chunk_w, grid if ad else grid * np.median(dist_w[:, -1]), tau)
            best = min(best, (float(mse.min()), bw, tau), key=lambda t: t[0])
        _, self.bandwidth_w_, self.agreement_ = best
        _, ind_t = self._zv_tree.query(self._zv, k=kj + 1)
        ind_t = ind_t[:, 1:]
        mask = self._mask(ind_t)
        self.theta_radius_ = np.linalg.norm(self._pose_diff(Theta, Theta[ind_t[:, -1:]])[:, 0],
                                            axis=1)

        def chunk_t(sl: slice) -> LooChunk:
            it = ind_t[sl]
            return (self._pose_diff(Theta[sl], Theta[it]), y[it], self.GR_[it], y[sl],
                    None if mask is None else mask[sl], None,
                    self.theta_radius_[it] if ad else None)

        self.bandwidth_theta_, _ = loo_bandwidth_chunked(
            n, chunk_t, grid if ad else grid * np.median(self.theta_radius_))

    def _forward_first_order(self, rows: Array, precision: Array | None = None
                             ) -> tuple[Array, Array]:
        """G of r* at ``rows`` from the forward model (first_order="forward",
        :mod:`~localization.gse.first_order`) and the residual precision used."""
        k = min(FORWARD_NEIGHBORS, len(self.theta_) - 1)
        return forward_gls_jacobians(
            self._ws, self.GR_, lambda r: self._zv_tree.query(self._zv[r], k=k + 1)[1][:, 1:],
            lambda r, ind: -self._pose_diff(self.theta_[r], self.theta_[ind]), rows,
            precision=precision, ridge=float(self.forward_ridge))

    def _setup(self) -> None:
        """Derived per-sample query structures (after fit or load)."""
        m = len(self.w_mean_)
        self._ws = np.ascontiguousarray(self.gse_.Z_[:, :m])  # contiguous: fast GEMM queries
        self._ws_sqn = (self._ws ** 2).sum(axis=1)
        self._ws_tree = cKDTree(self._ws) if m <= KDTREE_MAX_DIM else None
        if self.gse_.algorithm_ == "approximate":
            if getattr(self, "_ws_index", None) is None:
                self._ws_index = HNSWIndex(self._ws)
            elif self._ws_index.index.ntotal < len(self._ws):  # rows added by partial_fit
                self._ws_index.add(self._ws)
        self._zv = np.ascontiguousarray(self.gse_.Z_[:, m:])
        self._zv_tree = cKDTree(self._zv)  # pose space is low-dimensional
        self.embedding_ = self.gse_.embedding_
        self._memo = {}  # the last single-row query of r* and R* (queries.GSEQueryMixin)

    # --------------------------------------------------------------- persistence
    def save(self, path: str | Path) -> None:
        """Save to ``.npz`` (no pickles; settings as a JSON string)."""
        check_is_fitted(self, "gse_")
        save_regressor(self, path)

    @classmethod
    def load(cls, path: str | Path) -> GSERegressor:
        """Load a model written by :meth:`save`; ValueError if corrupt or incomplete."""
        return load_regressor(cls, path)

