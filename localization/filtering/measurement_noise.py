"""Measurement noise of the appearance measurements, estimated from held-out residuals.

Three pieces, all free functions on residual arrays:

- :func:`robust_covariance`: E[e e^T] of residual rows with
  :class:`sklearn.covariance.MinCovDet`, so that rare gross errors (an image that looks like
  a place metres away: aliasing) do not inflate R. The filter's NIS gate rejects those
  measurements at run time, so R must describe the others.
- :func:`to_body`: pose errors rotated into the robot's body frame (along track, cross
  track, heading). Appearance errors are anisotropic in that frame (an image pins the
  cross-track position better than the along-track one), so R is stored there and turned
  back to the world frame at the current heading: ``R(x) = T(yaw) R_body T(yaw)^T``.
- :func:`correlation_time`: the integrated autocorrelation time ``tau`` of each residual
  component along a driven sequence. Consecutive images are nearly the same image, so
  their errors are correlated; a Kalman filter that treats them as independent becomes
  over-confident by about ``tau``. Inflating R to ``tau R`` (per component) gives the
  filter the information it really receives: ``tau`` frames carry about one independent
  measurement.
- :func:`consistency_inflation`: what remains (errors that no white-noise model
  describes, e.g. a localizer a little off through a whole turn) is measured by running the
  filter on a recorded drive with known poses, and Q and R are inflated per body component
  until the filter's covariance matches its errors there (NEES calibration, robust: e^2 / P
  is clipped at chi2(1)'s 99th percentile, so the rare stretches where the filter is off
  do not set the scale).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import chi2
from sklearn.covariance import MinCovDet

from localization._validation import check_array
from localization.geometry import Array, to_body


def robust_covariance(residuals: ArrayLike, random_state: int = 0) -> Array:
    """Robust second moment E[e e^T] (k, k) of zero-mean residual rows ``e`` (n, k).

    Minimum covariance determinant (``assume_centered=True``), reweighted and rescaled by
    scikit-learn to be consistent for Gaussian data. Non-finite rows are dropped.

    Raises
    ------
    ValueError
        With fewer than ``5 k`` finite rows.
    """
    e = check_array(residuals, "residuals", finite=False)
    if e.ndim != 2:
        raise ValueError(f"residuals must be 2-D (n, k), got shape {e.shape}")
    e = e[np.all(np.isfinite(e), axis=1)]
    if len(e) < 5 * e.shape[1]:
        raise ValueError(f"need at least {5 * e.shape[1]} finite residuals to estimate a "
                         f"{e.shape[1]}x{e.shape[1]} noise covariance, got {len(e)}")
    C = MinCovDet(assume_centered=True, random_state=random_state).fit(e).covariance_
    C = 0.5 * (C + C.T)
    return C + 1e-9 * np.trace(C) / len(C) * np.eye(len(C))


def correlation_time(residuals: ArrayLike, covariance: ArrayLike | None = None,
                     block: int = 50, outlier_sigma: float = 3.0) -> Array:
    """Integrated autocorrelation time ``tau_j`` of each residual component (batch means).

    ``tau_j = B var(mean of blocks of B consecutive residuals) / var(residuals)``: the
    variance of a B-frame average is ``tau var / B`` instead of ``var / B``. Blocks as long
    as the filter's averaging window count the slow, metre-scale part of the error (a place
    whose images are all a little off), which an autocorrelation sum cut at small lags
    misses.

    Parameters
    ----------
    residuals : array_like (n, k)
        Residuals of consecutive frames of one drive, in time order (NaN rows allowed),
        n >= 4 * block.
    covariance : array_like (k, k), optional
        Robust covariance of the residuals; components beyond ``outlier_sigma`` standard
        deviations are gross errors (the filter's gate removes them) and set to 0 first.
    block : int
        Block length B in frames.
    outlier_sigma : float

    Returns
    -------
    tau : ndarray (k,), >= 1
    """
    e = check_array(residuals, "residuals", ndim=2, finite=False).copy()
    if block < 1 or len(e) < 4 * block:
        raise ValueError(f"residuals: need a (n, k) residual sequence with n >= 4 * block = {4 * block}, "
                         f"got shape {e.shape}")
    e[~np.isfinite(e)] = 0.0
    if covariance is not None:
        sd = np.sqrt(np.diag(np.asarray(covariance, dtype=np.float64)))
        e[np.abs(e) > outlier_sigma * sd] = 0.0
    e -= e.mean(axis=0)
    var = e.var(axis=0)
    nb = len(e) // block
    means = e[:nb * block].reshape(nb, block, -1).mean(axis=1)
    tau = block * (means ** 2).mean(axis=0) / np.where(var > 0, var, 1.0)
    return np.maximum(tau, 1.0)


def body_errors(means: ArrayLike, covs: ArrayLike, poses: ArrayLike) -> tuple[Array, Array]:
    """Estimation errors and covariances in the body frame of the true poses.

    Returns ``e`` (n, 3) = ``T(yaw)^T (mean - pose)`` (heading wrapped) and ``P_body``
    (n, 3, 3) = ``T^T P T``.
    """
    means, covs, poses = (np.asarray(a, dtype=np.float64) for a in (means, covs, poses))
    e = to_body(means - poses, poses[:, 2])
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    T = np.zeros((len(poses), 3, 3))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1], T[:, 2, 2] = c, s, -s, c, 1.0
    return e, T @ covs @ np.swapaxes(T, 1, 2)


#: upper bound of :func:`consistency_inflation`'s factors (a factor there: calibration failed)
MAX_INFLATION = 100.0
_CLIP = float(chi2.ppf(0.99, 1))
_CLIPPED_MEAN = float(chi2.cdf(_CLIP, 3) + _CLIP * chi2.sf(_CLIP, 1))  # E min(chi2(1), clip)


def consistency_inflation(run: Callable[[Array], tuple[Array, Array]], poses: ArrayLike,
                          iterations: int = 4, burn_in: int = 30, lost: float = 1.0,
                          max_alpha: float = MAX_INFLATION, start: ArrayLike | None = None) -> Array:
    """Per-component covariance inflation ``alpha`` (along, cross, heading) that makes a filter
    consistent on a recorded drive: in the body frame, ``min(e_j^2 / P_jj, c)`` has the mean of
    ``min(chi2(1), c)``, with ``c`` chi2(1)'s 99th percentile (6.63; that mean is 0.98).

    Scaling Q, R and P0 of a linear filter by the same factor leaves its estimates unchanged
    and scales P by that factor; per body component this holds approximately, so a few
    fixed-point steps ``alpha_j <- alpha_j mean(min(e_j^2 / P_jj, c)) / E min(chi2(1), c)``
    converge. Clipped, not the plain mean: with a NIS gate the premise fails for the tail. A
    wider gate lets more aliased measurements through, the filter errs more, the mean asks
    for a wider gate still: on a street-wide localizer of 5000 images the plain mean ran to
    the bound (100) on every component and the scripted agent reached 11 of 30 goals; with
    the median of e^2 / P (a robust statistic like this one) 26 (alpha 7, 22, 1.2). Only
    inflation is applied (``alpha >= 1``): a conservative component is left
    alone. Steps where the filter is lost (position error above ``lost`` metres) are left
    out: that is a failure for the recovery logic, not noise to scale every step by.

    Parameters
    ----------
    run : callable
        ``run(alpha) -> (means (n, 3), covs (n, 3, 3))``: the filter over the drive with the
        noise covariances inflated by ``alpha`` (3,).
    poses : array_like (n, 3)
        True poses of the drive.
    iterations : int
    burn_in : int
        Steps ignored at the start (the initial transient).
    lost : float
        Position error (m) above which a step is left out.
    max_alpha : float
        Upper bound of each factor.
    start : array_like (3,), optional
        Initial alpha (default ones).
    """
    poses = np.asarray(poses, dtype=np.float64)
    alpha = np.ones(3) if start is None else np.asarray(start, dtype=np.float64).copy()
    for _ in range(iterations):
        means, covs = run(alpha)
        e, P = body_errors(means[burn_in:], covs[burn_in:], poses[burn_in:])
        ok = np.hypot(e[:, 0], e[:, 1]) < lost
        if ok.sum() < 10:
            break
        r = e[ok] ** 2 / np.diagonal(P[ok], axis1=1, axis2=2)
        ratio = np.mean(np.minimum(r, _CLIP), axis=0) / _CLIPPED_MEAN
        alpha = np.clip(alpha * ratio, 1.0, max_alpha)
    return alpha


def inflate(C: ArrayLike, alpha: ArrayLike) -> Array:
    """``D C D`` with ``D = diag(sqrt(alpha))``: covariance C with component j scaled by alpha_j."""
    C = check_array(C, "C", ndim=2)
    if C.shape[0] != C.shape[1]:
        raise ValueError(f"C must be a square covariance matrix, got shape {C.shape}")
    alpha = check_array(alpha, "alpha", shape=(len(C),))
    if np.any(alpha < 0):
        raise ValueError(f"alpha must be non-negative factors, got {alpha}")
    d = np.sqrt(alpha)
    return d[:, None] * C * d[None, :]


def check_alpha(alpha: ArrayLike) -> Array:
    """A body-frame inflation: a positive number or (3,) positive numbers."""
    a = check_array(alpha, "alpha")
    if a.shape not in ((), (3,)) or np.any(a <= 0):
        raise ValueError(f"alpha must be a positive number or 3 positive numbers, got {alpha}")
    return a
