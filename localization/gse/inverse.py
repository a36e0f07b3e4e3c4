"""The inverse of Phi*: an image's pose by Gauss-Newton on its whitened feature residual,
started at psi*(w) (docs/method.md §8.4).

psi*(w) = g_v(r*(w)) reads the pose off the embedding: a kernel average over the images
whose features lie nearest, which blurs where the samples are sparse (a city's street
surface at every heading). Phi* models the features of every pose, with its exact Jacobian,
so the pose that best explains the image under the features' noise R,

    theta_hat = argmin_theta  e(theta)^T e(theta),   e(theta) = L (w - Phi*(theta)),
    L = chol(R)^-1 (the whitener: L R L^T = I),

is a few damped Gauss-Newton steps away from psi*(w): with J = L dPhi*/dtheta,

    step = pinv(J) e,   theta <- theta + a step,   a = 1, 1/2, ... until the cost falls

(at most ``max_halvings`` halvings; a row without descent keeps its pose; periodic columns
are wrapped). r*(w) and R* are no help here: psi*(w) already solves R*(theta) = r*(w) to
numerical precision.

A gross error of psi*(w) (a fold of the embedding, a look-alike view: the pose many metres
or degrees off) is not a few steps away. :func:`verify_poses` checks psi*(w) against the
poses of the training images whose features lie nearest to w (retrieval, then verification
by the model, as visual-localization pipelines verify their retrieved candidates): with
the same whitened cost,

    theta_hat = theta_j*  if  margin * e(theta_j*)^T e(theta_j*) < e(psi*)^T e(psi*),
    j* = argmin_j e(theta_j)^T e(theta_j)  over the k nearest training images j,

else psi*(w). The margin keeps psi*'s sub-sample resolution wherever it explains the image
about as well as the best candidate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_array, check_int, check_real
from localization.geometry import wrap_angle
from localization.gse.graph import Array

__all__ = ["feature_whitener", "refine_poses", "residual_whitener", "verify_poses"]


def feature_whitener(cov: ArrayLike) -> Array:
    """The whitener L (m, m) of a features' noise covariance R (m, m): ``L R L^T = I``
    (a ridge of 1e-9 of R's mean variance keeps a rank-deficient R invertible).

    Raises
    ------
    ValueError
        If ``cov`` is not a finite symmetric positive semi-definite (m, m) matrix.
    """
    R = check_array(cov, "cov")
    if R.ndim != 2 or R.shape[0] != R.shape[1] or not np.allclose(R, R.T, atol=1e-12 * np.abs(R).max()):
        raise ValueError(f"cov must be a symmetric (m, m) covariance, got shape {R.shape}")
    R = 0.5 * (R + R.T) + 1e-9 * max(float(np.trace(R)) / len(R), 1e-300) * np.eye(len(R))
    try:
        C = np.linalg.cholesky(R)
    except np.linalg.LinAlgError as err:
        raise ValueError("cov must be positive semi-definite (its Cholesky factor failed)") from err
    return np.linalg.solve(C, np.eye(len(R)))


def residual_whitener(reg: Any, W: ArrayLike, Theta: ArrayLike) -> Array:
    """The whitener L (m, m) of the features' residuals about Phi*: :func:`feature_whitener`
    of the covariance of ``W - Phi*(Theta)`` over the rows where both are finite (e.g. the
    training split's own, where no held-out noise drive exists; :func:`verify_poses` only
    compares costs, so only R's shape matters).

    Parameters
    ----------
    reg : GSERegressor
        Fitted; its ``predict_features`` gives Phi*.
    W : ndarray (n, m)
        Features.
    Theta : ndarray (n, d)
        Their poses in the regressor's coordinates.

    Raises
    ------
    ValueError
        If the shapes disagree or fewer than m + 1 rows have finite residuals.
    """
    W = check_array(W, "W", finite=False)
    Theta = check_array(Theta, "Theta", finite=False)
    if W.ndim != 2 or Theta.ndim != 2 or len(W) != len(Theta):
        raise ValueError(f"W (n, m) and Theta (n, d) must have the same rows, got W {W.shape} "
                         f"and Theta {Theta.shape}")
    live = _live_rows(W, Theta)
    E = W[live] - reg.predict_features(Theta[live]) if len(live) else W[:0]
    E = E[np.all(np.isfinite(E), axis=1)]
    if len(E) <= W.shape[1]:
        raise ValueError(f"residual_whitener needs more than m = {W.shape[1]} rows with finite "
                         f"residuals W - Phi*(Theta), got {len(E)}")
    return feature_whitener(np.cov(E.T))


def refine_poses(reg: Any, W: ArrayLike, theta0: ArrayLike, whitener: ArrayLike,
                 n_iter: int = 3, max_halvings: int = 5) -> Array:
    """Damped Gauss-Newton on ``|L (w - Phi*(theta))|^2`` from ``theta0`` (see the module
    docstring), every row at once.

    Parameters
    ----------
    reg : GSERegressor
        Fitted; its ``features_and_jacobian`` gives Phi* and dPhi*/dtheta.
    W : ndarray (n, m)
        Features.
    theta0 : ndarray (n, d)
        Start poses in the regressor's coordinates (psi*(W)); NaN rows stay NaN.
    whitener : ndarray (m, m)
        L of :func:`feature_whitener`.
    n_iter : int
        Gauss-Newton steps (3: on tuning cities 12-13 the gain came in 2-3 steps).
    max_halvings : int
        Step halvings tried per step before a row stops.

    Returns
    -------
    theta : ndarray (n, d)
    """
    W, theta, L = _check_inputs(W, theta0, whitener)
    n_iter = check_int(n_iter, "n_iter", low=0)
    max_halvings = check_int(max_halvings, "max_halvings", low=0)
    live = _live_rows(W, theta)
    if not len(live) or not n_iter:
        return theta
    e, J, cost = _whitened(reg, W[live], theta[live], L)
    for _ in range(n_iter):
        keep = np.isfinite(cost)
        live, e, J, cost = live[keep], e[keep], J[keep], cost[keep]
        if not len(live):
            break
        step = (np.linalg.pinv(J) @ e[:, :, None])[..., 0]
        moved = _line_search(reg, W[live], theta[live], step, L, cost, max_halvings)
        theta[live], e, J, cost = moved
    return theta


def verify_poses(reg: Any, W: ArrayLike, theta0: ArrayLike, whitener: ArrayLike,
                 n_candidates: int = 10, margin: float = 3.0) -> tuple[Array, Array]:
    """psi*(w) checked against the poses of the ``n_candidates`` training images nearest to
    w in feature space (see the module docstring), every row at once.

    Parameters
    ----------
    reg : GSERegressor
        Fitted; its ``kneighbors``, ``theta_`` and ``predict_features`` are used.
    W : ndarray (n, m)
        Features.
    theta0 : ndarray (n, d)
        psi*(W) in the regressor's coordinates; NaN rows (out of domain) stay NaN.
    whitener : ndarray (m, m)
        L of :func:`feature_whitener`.
    n_candidates : int
        Training images retrieved per row (10: on tuning cities 11-12 20 gave the same
        mean, docs/method.md §8.4).
    margin : float
        How many times better a candidate must explain w than psi*(w) (>= 1; 3 chosen over
        2 and 4 on tuning cities 11-12, docs/method.md §8.4).

    Returns
    -------
    theta : ndarray (n, d)
    switched : ndarray (n,) of bool
        Rows where a candidate replaced psi*(w).
    """
    W, theta, L = _check_inputs(W, theta0, whitener)
    k = check_int(n_candidates, "n_candidates", low=1)
    margin = check_real(margin, "margin", low=1.0)
    switched = np.zeros(len(W), dtype=bool)
    live = _live_rows(W, theta)
    if not len(live):
        return theta, switched
    _, ind = reg.kneighbors(W[live], k)
    cand = reg.theta_[ind]  # (n_live, k, d)
    costs = _costs(reg, np.repeat(W[live], ind.shape[1] + 1, axis=0),
                   np.concatenate([theta[live, None], cand], axis=1).reshape(-1, theta.shape[1]),
                   L).reshape(len(live), -1)
    best = np.argmin(costs[:, 1:], axis=1)
    better = margin * costs[np.arange(len(live)), 1 + best] < costs[:, 0]
    rows = live[better]
    theta[rows] = cand[better, best[better]]
    switched[rows] = True
    return theta, switched


def _check_inputs(W: ArrayLike, theta0: ArrayLike, whitener: ArrayLike
                  ) -> tuple[Array, Array, Array]:
    """``W`` (n, m), a copy of ``theta0`` (n, d) and ``whitener`` (m, m) as float arrays
    (ValueError naming the three when their shapes disagree)."""
    W = check_array(W, "W", finite=False)
    theta = check_array(theta0, "theta0", finite=False).copy()
    L = check_array(whitener, "whitener")
    if W.ndim != 2 or theta.ndim != 2 or len(W) != len(theta) or L.shape != (W.shape[1],) * 2:
        raise ValueError(f"W (n, m), theta0 (n, d) and whitener (m, m) disagree: W {W.shape}, "
                         f"theta0 {theta.shape}, whitener {L.shape}")
    return W, theta, L


def _live_rows(W: Array, theta: Array) -> Array:
    """Rows with finite features and a finite start pose (the others keep theirs)."""
    return np.flatnonzero(np.all(np.isfinite(theta), axis=1) & np.all(np.isfinite(W), axis=1))


def _costs(reg: Any, W: Array, theta: Array, L: Array) -> Array:
    """Whitened costs ``|L (w - Phi*(theta))|^2`` (n,), inf where Phi* is undefined."""
    ok = np.flatnonzero(np.all(np.isfinite(theta), axis=1))
    cost = np.full(len(W), np.inf)
    if len(ok):
        c = np.sum(((W[ok] - reg.predict_features(theta[ok])) @ L.T) ** 2, axis=1)
        cost[ok] = np.where(np.isfinite(c), c, np.inf)
    return cost


def _whitened(reg: Any, W: Array, theta: Array, L: Array) -> tuple[Array, Array, Array]:
    """Whitened residuals e (n, m), Jacobians J = L dPhi*/dtheta (n, m, d) and costs (n,)
    (inf where Phi* is undefined)."""
    phi, dphi = reg.features_and_jacobian(theta)
    e = (W - phi) @ L.T
    cost = np.sum(e ** 2, axis=1)
    return e, L @ dphi, np.where(np.isfinite(cost), cost, np.inf)


def _line_search(reg: Any, W: Array, theta: Array, step: Array, L: Array, cost: Array,
                 max_halvings: int) -> tuple[Array, Array, Array, Array]:
    """Each row's step, halved until its cost falls; rows that never descend keep their pose
    and get cost inf (they stop)."""
    periodic = list(getattr(reg, "periodic", ()))
    theta = theta.copy()
    out_e = np.zeros((len(theta), W.shape[1]))
    out_J = np.zeros((len(theta), W.shape[1], theta.shape[1]))
    new_cost = np.full(len(theta), np.inf)
    pending, a = np.arange(len(theta)), 1.0
    for _ in range(max_halvings + 1):
        trial = theta[pending] + a * step[pending]
        trial[:, periodic] = wrap_angle(trial[:, periodic])
        e, J, c = _whitened(reg, W[pending], trial, L)
        down = c < cost[pending]
        rows = pending[down]
        theta[rows], out_e[rows], out_J[rows], new_cost[rows] = trial[down], e[down], J[down], c[down]
        pending, a = pending[~down], 0.5 * a
        if not len(pending):
            break
    return theta, out_e, out_J, new_cost
