"""Heteroscedastic measurement noise R(theta): one global R scaled by where the maps are weak.

One global R (:mod:`localization.filtering.measurement_noise`) describes the average place.
Where the training sample is thin or the GSE maps are steep, held-out errors are larger than
that average and a filter with the global R is over-confident there; where they are
smaller, it wastes information. Here the held-out residuals of the K-fold refits are
regressed on the local geometry of the maps at their poses, and R is scaled by the result::

    R_body(theta) = s(theta) R_body,          R(theta) = T(yaw) R_body(theta) T(yaw)^T

    y_i      = min(e_i^T R_body^-1 e_i, c) / k              (k = dim e, c = chi2_k 99.7 %)
    g        = [log(d(theta) / d_ref), log sv_1..3 (dR*/dtheta)(theta), log(u(w) / u_ref),
                log n(theta)]
    E[y | theta, w] = exp(b0 + b^T g)                          (Gamma GLM, log link)
    s(theta, w) = clip(exp(b0 + b^T g) / m, min_scale, max_scale)

- ``d(theta)``: distance to the ``density_neighbors``-th nearest training pose (in
  ``(x, y, L cos yaw, L sin yaw)``, ``L = heading_scale`` metres per radian), ``d_ref`` its
  median over the held-out poses. For a K-fold residual it is measured to that fold's
  training poses: the sample that made the map it was predicted with.
- ``sv``: the singular values of the Jacobian of R* (the maps' steepness and conditioning).
- ``u(w)``: the image's novelty, the distance of its features w from the learned manifold
  (``|w - g_u(r*(w))|``, reduce-then-recover), ``u_ref`` its median over the held-out
  images: an unfamiliar frame (another light, an occluder) lies off the manifold of the
  training images and its R grows. Learned from held-out daylight images only; a query
  without an image (``novelty=None``) counts as a typical frame (``u = u_ref``).
- ``n(theta)``: the held-out scores ``y`` of the ``n_neighbors`` nearest held-out poses,
  averaged with ``prior_weight`` pseudo-scores at their mean and divided by that mean (a
  kNN smoother shrunk to 1; without the pose itself during the fit).
- Bounds: the density, novelty and neighbour coefficients are >= 0 (the neighbours' <= 1),
  so R never shrinks where the sample thins out or the image is less familiar; gross errors are clipped at ``c`` (the gate
  rejects them at run time, as for the global R).
- ``m``: the mean of ``exp(b0 + b^T g)`` over the held-out poses, so ``s`` averages 1 there:
  the level stays the global R's (its correlation-time inflation and the consistency
  calibration still apply); only its distribution over the map is learned. When the global
  R comes from a recorded drive, :meth:`HeteroscedasticNoise.normalize` makes ``s`` average
  1 over that drive's frames instead.

``s > 0`` times an SPD matrix, with an eigenvalue floor (:func:`scaled_covariance`), is SPD
by construction. Where the maps have no value (``dR*/dtheta`` is NaN: out of the training
domain) ``s`` is NaN.
"""

from __future__ import annotations

from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize
from scipy.stats import chi2
from sklearn.exceptions import NotFittedError
from sklearn.neighbors import NearestNeighbors

from localization._validation import check_array, check_int, check_real
from localization.geometry import Array

__all__ = ["HeteroscedasticNoise", "fit_log_gamma", "pose_points", "scaled_covariance",
           "squared_scores"]

#: settings of :class:`HeteroscedasticNoise` in the order they are saved
PARAMS = ("n_neighbors", "density_neighbors", "heading_scale", "prior_weight",
          "clip_probability", "min_scale", "max_scale", "ridge")
_INTS = ("n_neighbors", "density_neighbors")
_EIGEN_FLOOR = 1e-12


def pose_points(poses: ArrayLike, heading_scale: float) -> Array:
    """Poses (n, 3) as points (n, 4) ``[x, y, L cos yaw, L sin yaw]`` of a metric with the
    heading periodic (``L = heading_scale``, metres per radian for small angles)."""
    p = check_array(poses, "poses", shape=(None, 3), finite=False, what="[x, y, yaw]")
    return np.column_stack([p[:, 0], p[:, 1], heading_scale * np.cos(p[:, 2]),
                            heading_scale * np.sin(p[:, 2])])


def squared_scores(residuals: ArrayLike, covariance: ArrayLike,
                   clip_probability: float = 0.997) -> Array:
    """``min(e^T C^-1 e, c) / k`` (n,) of residual rows ``e`` (n, k) (NaN rows stay NaN);
    ``c = chi2.ppf(clip_probability, k)``. Mean 1 for Gaussian errors of covariance C
    (a little less with the clip)."""
    e = check_array(residuals, "residuals", ndim=2, finite=False)
    C = check_array(covariance, "covariance", shape=(e.shape[1], e.shape[1]))
    L = np.linalg.cholesky(0.5 * (C + C.T))
    d2 = np.sum(np.linalg.solve(L, np.nan_to_num(e).T) ** 2, axis=0)
    d2[~np.all(np.isfinite(e), axis=1)] = np.nan
    k = e.shape[1]
    return np.minimum(d2, chi2.ppf(clip_probability, k)) / k


def fit_log_gamma(X: ArrayLike, y: ArrayLike, bounds: list[tuple[float | None, float | None]],
                  ridge: float = 1e-3) -> Array:
    """Coefficients ``b`` (p + 1,) of ``E[y | x] = exp(b0 + x^T b[1:])`` (Gamma GLM, log link).

    Minimises the Gamma deviance ``sum(y exp(-eta) + eta)`` plus ``ridge |b[1:]|^2`` (n
    times: it does not fade with n), with box ``bounds`` on ``b[1:]`` (L-BFGS-B).

    Parameters
    ----------
    X : (n, p) finite features; y : (n,) positive targets; bounds : p (low, high) pairs.
    """
    X = check_array(X, "X", ndim=2)
    y = check_array(y, "y", shape=(len(X),))
    if np.any(y <= 0):
        raise ValueError("y must be positive")
    A = np.column_stack([np.ones(len(X)), X])
    n = len(y)

    def loss(b: Array) -> tuple[float, Array]:
        eta = A @ b
        r = y * np.exp(-eta)
        pen = ridge * n * np.sum(b[1:] ** 2)
        grad = A.T @ (1.0 - r)
        grad[1:] += 2.0 * ridge * n * b[1:]
        return float(np.sum(r + eta) + pen), grad

    b0 = np.zeros(A.shape[1])
    b0[0] = np.log(np.mean(y))
    res = minimize(loss, b0, jac=True, method="L-BFGS-B", bounds=[(None, None), *bounds])
    return np.asarray(res.x, dtype=np.float64)


def scaled_covariance(R: ArrayLike, scale: ArrayLike, floor: float = _EIGEN_FLOOR) -> Array:
    """``s R`` (n, k, k) for scales s (n,) and an SPD matrix R (k, k), symmetrised, its
    eigenvalues floored at ``floor * trace(R) / k``; NaN matrices where s is NaN."""
    R = check_array(R, "R", ndim=2)
    s = check_array(scale, "scale", ndim=1, finite=False)
    if np.any(s[np.isfinite(s)] <= 0):
        raise ValueError("scale must be positive")
    w, V = np.linalg.eigh(0.5 * (R + R.T))
    w = np.maximum(w, floor * np.trace(R) / len(R))
    out = s[:, None, None] * ((V * w) @ V.T)[None]
    return 0.5 * (out + np.swapaxes(out, 1, 2))


class HeteroscedasticNoise:
    """Relative scale ``s(theta)`` of a global measurement noise R (module docstring).

    Parameters
    ----------
    n_neighbors : int
        Held-out poses of the neighbour smoother ``n(theta)``.
    density_neighbors : int
        k of the density distance ``d(theta)`` (k-th nearest training pose).
    heading_scale : float
        Metres per radian of the pose metric (:func:`pose_points`).
    prior_weight : float
        Pseudo-scores at the mean in the neighbour smoother (shrinkage to 1).
    clip_probability : float
        Squared Mahalanobis residuals are clipped at chi2_k's quantile of this probability.
    min_scale, max_scale : float
        Bounds of ``s`` (0 < min_scale <= 1 <= max_scale).
    ridge : float
        Ridge penalty of the log-linear Gamma regression (:func:`fit_log_gamma`).

    Attributes
    ----------
    poses_ : (n, 3) held-out poses; scores_ : (n,) their scores y.
    coef_ : (p + 1,) intercept and coefficients of [log d, log sv (3), log u, log n] (p = 6).
    center_, spread_ : (p,) standardisation of the features.
    density_ref_ : float, d_ref (metres); novelty_ref_ : float, u_ref; level_ : float, m.
    """

    def __init__(self, n_neighbors: int = 20, density_neighbors: int = 5,
                 heading_scale: float = 1.0, prior_weight: float = 10.0,
                 clip_probability: float = 0.997, min_scale: float = 0.25,
                 max_scale: float = 100.0, ridge: float = 1e-3) -> None:
        self.n_neighbors = n_neighbors
        self.density_neighbors = density_neighbors
        self.heading_scale = heading_scale
        self.prior_weight = prior_weight
        self.clip_probability = clip_probability
        self.min_scale = min_scale
        self.max_scale = max_scale
        self.ridge = ridge

    def _check_params(self) -> None:
        check_int(self.n_neighbors, "n_neighbors", low=1)
        check_int(self.density_neighbors, "density_neighbors", low=1)
        check_real(self.heading_scale, "heading_scale", low=0.0, low_open=True)
        check_real(self.prior_weight, "prior_weight", low=0.0)
        check_real(self.clip_probability, "clip_probability", low=0.0, high=1.0,
                   low_open=True, high_open=True)
        check_real(self.min_scale, "min_scale", low=0.0, high=1.0, low_open=True)
        check_real(self.max_scale, "max_scale", low=1.0)
        check_real(self.ridge, "ridge", low=0.0)

    def get_params(self) -> dict[str, Any]:
        """Constructor arguments."""
        return {k: getattr(self, k) for k in PARAMS}

    # ------------------------------------------------------------ geometry
    def density_index(self, train_poses: ArrayLike) -> NearestNeighbors:
        """The neighbour index of training poses (n, 3) for :meth:`geometry`."""
        self._check_params()
        pts = pose_points(train_poses, float(self.heading_scale))
        if len(pts) < int(self.density_neighbors) + 1:
            raise ValueError(f"train_poses: need more than density_neighbors="
                             f"{self.density_neighbors} poses, got {len(pts)}")
        return NearestNeighbors(n_neighbors=int(self.density_neighbors)).fit(pts)

    def geometry(self, index: NearestNeighbors, poses: ArrayLike, jacobians: ArrayLike,
                 novelty: ArrayLike | None = None) -> Array:
        """Local features (n, 5) ``[d, sv_1, sv_2, sv_3, u]`` at poses (n, 3): the density
        distance to the training poses of ``index`` (:meth:`density_index`), the singular
        values of the Jacobians (n, q, 3) of R* and the images' novelty u (n,) (None: a
        typical frame, NaN in the last column until fitted); NaN rows where a pose or
        Jacobian is not finite."""
        pts = pose_points(poses, float(self.heading_scale))
        J = check_array(jacobians, "jacobians", ndim=3, finite=False)
        if len(J) != len(pts) or J.shape[2] != 3:
            raise ValueError(f"jacobians must have shape ({len(pts)}, q, 3), got {J.shape}")
        out = np.full((len(pts), 5), np.nan)
        ok = np.all(np.isfinite(pts), axis=1) & np.all(np.isfinite(J), axis=(1, 2))
        if ok.any():
            dist, _ = index.kneighbors(pts[ok])
            sv = np.linalg.svd(J[ok], compute_uv=False)
            out[ok, 0] = dist[:, -1]
            out[ok, 1:1 + min(sv.shape[1], 3)] = sv[:, :3]
        if novelty is None:
            out[ok, 4] = getattr(self, "novelty_ref_", np.nan)
        else:
            u = check_array(novelty, "novelty", shape=(len(pts),), finite=False)
            out[ok, 4] = u[ok]
        return out

    def _design(self, geometry: Array, neighbours: Array) -> Array:
        d = np.maximum(geometry[:, :1], 1e-6 * self.density_ref_) / self.density_ref_
        sv = np.maximum(geometry[:, 1:4], 1e-12)
        u = np.maximum(geometry[:, 4:], 1e-6 * self.novelty_ref_) / self.novelty_ref_
        return np.log(np.column_stack([d, sv, u, neighbours]))

    def _neighbours(self, poses: Array, exclude_self: bool) -> Array:
        """The smoother ``n(theta)`` (n,) at poses (rows must be finite)."""
        k = min(int(self.n_neighbors) + exclude_self, len(self.poses_))
        _, ind = self._index.kneighbors(pose_points(poses, float(self.heading_scale)), k)
        if exclude_self:
            ind = ind[:, 1:]
        mean = float(np.mean(self.scores_))
        w = float(self.prior_weight)
        return (self.scores_[ind].sum(axis=1) + w * mean) / (ind.shape[1] + w) / mean

    # ----------------------------------------------------------------- fit
    def fit(self, residuals: ArrayLike, poses: ArrayLike, covariance: ArrayLike,
            geometry: ArrayLike) -> Self:
        """Fit ``s`` on held-out residuals.

        Parameters
        ----------
        residuals : (n, k) held-out residuals (NaN rows allowed: left out).
        poses : (n, 3) their true poses.
        covariance : (k, k) the global R they are scored against.
        geometry : (n, 5) :meth:`geometry` at the poses with the images' novelty (for K-fold
            residuals: against each fold's training poses and maps).
        """
        self._check_params()
        e = check_array(residuals, "residuals", ndim=2, finite=False)
        poses = check_array(poses, "poses", shape=(len(e), 3), what="[x, y, yaw]")
        geometry = check_array(geometry, "geometry", shape=(len(e), 5), finite=False)
        y = squared_scores(e, covariance, float(self.clip_probability))
        ok = np.isfinite(y) & np.all(np.isfinite(geometry), axis=1) & (y > 0)
        need = max(20, 2 * int(self.n_neighbors))
        if ok.sum() < need:
            raise ValueError(f"residuals: need at least {need} finite held-out residuals with "
                             f"finite geometry, got {int(ok.sum())}")
        self.poses_, self.scores_, geometry = poses[ok], y[ok], geometry[ok]
        self._index = NearestNeighbors().fit(pose_points(self.poses_, float(self.heading_scale)))
        self.density_ref_ = float(np.median(geometry[:, 0]))
        self.novelty_ref_ = float(max(np.median(geometry[:, 4]), 1e-12))
        X = self._design(geometry, self._neighbours(self.poses_, exclude_self=True))
        self.center_, self.spread_ = X.mean(axis=0), np.maximum(X.std(axis=0), 1e-9)
        self.center_[0] = 0.0  # log(d / d_ref): keep the median density at 0
        Xs = (X - self.center_) / self.spread_
        bounds = [(0.0, None), (None, None), (None, None), (None, None), (0.0, None),
                  (0.0, float(self.spread_[-1]))]  # exponent of n(theta) in [0, 1]
        self.coef_ = fit_log_gamma(Xs, self.scores_, bounds, float(self.ridge))
        self.level_ = 1.0
        self.level_ = float(np.mean(self._relative(X)))
        return self

    def normalize(self, poses: ArrayLike, geometry: ArrayLike) -> Self:
        """Rescale so that ``s`` (before its clip) averages 1 over these poses and images
        (e.g. the drive the global R was estimated on: that drive then sets the level, as
        it does for the global R)."""
        self._check_fitted()
        poses = check_array(poses, "poses", shape=(None, 3), finite=False, what="[x, y, yaw]")
        geometry = check_array(geometry, "geometry", shape=(len(poses), 5), finite=False)
        ok = np.all(np.isfinite(geometry), axis=1) & np.all(np.isfinite(poses), axis=1)
        if not ok.any():
            raise ValueError("normalize: no pose with finite geometry")
        X = self._design(geometry[ok], self._neighbours(poses[ok], exclude_self=False))
        self.level_ *= float(np.mean(self._relative(X)))
        return self

    def _relative(self, X: Array) -> Array:
        """``exp(b0 + b^T g) / m`` (n,) of design rows X (n, 6)."""
        return np.exp(self.coef_[0] + ((X - self.center_) / self.spread_) @ self.coef_[1:]) \
            / self.level_

    def scale(self, poses: ArrayLike, geometry: ArrayLike) -> Array:
        """``s(theta, w)`` (n,) at poses (n, 3) with their :meth:`geometry` (n, 5); NaN where
        the geometry is NaN (the maps have no value there)."""
        self._check_fitted()
        poses = check_array(poses, "poses", shape=(None, 3), finite=False, what="[x, y, yaw]")
        geometry = check_array(geometry, "geometry", shape=(len(poses), 5), finite=False)
        out = np.full(len(poses), np.nan)
        ok = np.all(np.isfinite(geometry), axis=1) & np.all(np.isfinite(poses), axis=1)
        if ok.any():
            X = self._design(geometry[ok], self._neighbours(poses[ok], exclude_self=False))
            out[ok] = np.clip(self._relative(X), self.min_scale, self.max_scale)
        return out

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError("this HeteroscedasticNoise is not fitted yet: call fit() first")

    # ---------------------------------------------------------------- state
    def get_state(self) -> dict[str, Array]:
        """The fitted model as named arrays (no pickle): :meth:`from_state` reads them."""
        self._check_fitted()
        return {"params": np.array([float(getattr(self, k)) for k in PARAMS]),
                "poses": self.poses_, "scores": self.scores_, "coef": self.coef_,
                "center": self.center_, "spread": self.spread_,
                "reference": np.array([self.density_ref_, self.novelty_ref_, self.level_])}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> HeteroscedasticNoise:
        """Rebuild a model written by :meth:`get_state` (ValueError if incomplete)."""
        missing = {"params", "poses", "scores", "coef", "center", "spread", "reference"} - set(state)
        if missing:
            raise ValueError(f"heteroscedastic noise state: missing {sorted(missing)}")
        params = np.asarray(state["params"], dtype=np.float64)
        if params.shape != (len(PARAMS),):
            raise ValueError(f"heteroscedastic noise state: params must have shape "
                             f"({len(PARAMS)},), got {params.shape}")
        model = cls(**{k: int(v) if k in _INTS else float(v) for k, v in zip(PARAMS, params)})
        model._check_params()
        model.poses_ = check_array(state["poses"], "poses", shape=(None, 3))
        model.scores_ = check_array(state["scores"], "scores", shape=(len(model.poses_),))
        model.coef_ = check_array(state["coef"], "coef", shape=(7,))
        model.center_ = check_array(state["center"], "center", shape=(6,))
        model.spread_ = check_array(state["spread"], "spread", shape=(6,))
        model.density_ref_, model.novelty_ref_, model.level_ = (float(v) for v in check_array(
            state["reference"], "reference", shape=(3,)))
        model._index = NearestNeighbors().fit(pose_points(model.poses_, model.heading_scale))
        return model
