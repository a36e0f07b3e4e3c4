"""Jacobian Regression (JR): kernel average of first-order Taylor expansions.

Given sample inputs ``x_i``, outputs ``y_i`` and Jacobian estimates ``G_i``
(docs/method.md §9)::

    f*(x) = sum_i K(x, x_i) [y_i + G_i (x - x_i)] / sum_i K(x, x_i)

with the exact derivative::

    df*/dx = sum_i w_i G_i + sum_i w_i (l_i - f*(x)) grad_x log K(x, x_i)^T,

``w_i = K_i / sum K``, ``l_i = y_i + G_i (x - x_i)``; for the Gaussian kernel
``grad_x log K = -(x - x_i) / sigma^2``. JR is exact on affine functions (with
exact ``G_i``) for any kernel.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from localization.gse.graph import Array, brute_knn, softmax_weights
from localization.gse.validation import check_2d

BANDWIDTH_GRID = (0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0)
#: Factors (of the median y-distance to the k-th neighbour) tried by ``agreement="auto"``.
AGREEMENT_GRID = (0.5, 1.0, 2.0, 4.0)


def jacobian_regression(dX: Array, Y_nb: Array, G_nb: Array, logw: Array,
                        grad_logw: Array | None = None) -> tuple[Array, Array | None, Array]:
    """JR prediction (and exact Jacobian) from precomputed neighbourhoods.

    Parameters
    ----------
    dX : ndarray of shape (n, k, dx)
        ``x - x_j`` for the k neighbours of each query.
    Y_nb : ndarray of shape (n, k, dy)
        Outputs ``y_j`` at the neighbours.
    G_nb : ndarray of shape (n, k, dy, dx)
        Jacobians ``G_j`` at the neighbours.
    logw : ndarray of shape (n, k)
        Log kernel values (``-inf`` excludes a neighbour).
    grad_logw : ndarray of shape (n, k, dx), optional
        ``grad_x log K(x, x_j)``; if given the exact Jacobian is returned.

    Returns
    -------
    f : ndarray of shape (n, dy)
    J : ndarray of shape (n, dy, dx) or None
    log_kernel_sum : ndarray of shape (n,)
        log of the (unnormalised) kernel sum, for out-of-domain checks.
    """
    w, log_sum = softmax_weights(logw)
    ell = Y_nb + np.einsum("nkab,nkb->nka", G_nb, dX)
    f = np.einsum("nk,nka->na", w, ell)
    J = None
    if grad_logw is not None:
        J = np.einsum("nk,nkab->nab", w, G_nb)
        J += np.einsum("nk,nka,nkb->nab", w, ell - f[:, None, :], grad_logw)
    return f, J, log_sum


def agreement_factor(ell: Array, logw: Array, G_nb: Array, tau: float, jacobian: bool
                     ) -> tuple[Array, Array | None]:
    """First-order agreement of the neighbours' Taylor predictions ``ell`` (n, k, dy).

    The anchor of each query is the prediction with the largest kernel-weighted density
    ``sum_j w_j exp(-|ell_i - ell_j|^2 / (2 tau^2))``; every neighbour is then weighted by
    ``exp(-|ell_j - ell_anchor|^2 / (2 tau^2))``. Neighbours that are close in the input
    but belong to another part of the manifold (a look-alike place, the other side of a
    cut) predict far-away outputs and drop out, even when the kernel alone would give
    them half the weight. Returns the log factor (n, k) and, if ``jacobian``, its
    gradient (n, k, dx) with the anchor held fixed (piecewise constant):
    ``-(G_j - G_anchor)^T (ell_j - ell_anchor) / tau^2``.
    """
    w, _ = softmax_weights(logw)
    d2 = ((ell[:, :, None, :] - ell[:, None, :, :]) ** 2).sum(axis=3)  # (n, k, k)
    anchor = np.argmax(np.einsum("nij,nj->ni", np.exp(-0.5 * d2 / tau ** 2), w), axis=1)
    rows = np.arange(len(ell))
    diff = ell - ell[rows, anchor][:, None, :]
    log_a = -0.5 * (diff ** 2).sum(axis=2) / tau ** 2
    grad = None
    if jacobian:
        dG = G_nb - G_nb[rows, anchor][:, None]
        grad = -np.einsum("nkab,nka->nkb", dG, diff) / tau ** 2
    return log_a, grad


def gaussian_jr(dX: Array, Y_nb: Array, G_nb: Array, bandwidth: float | Array,
                mask: NDArray[np.bool_] | None = None, jacobian: bool = False,
                log_factor: Array | None = None, agreement: float | None = None
                ) -> tuple[Array, Array | None, Array]:
    """:func:`jacobian_regression` with the Gaussian kernel ``exp(-|dx|^2 / (2 sigma^2))``,
    optionally times a factor ``exp(log_factor)`` (n, k) treated as locally constant
    (not differentiated).

    ``bandwidth`` is one number, or an array (n, k) of per-neighbour bandwidths
    ``sigma_j`` (the sample-point adaptive kernel: each training point carries its
    own bandwidth, so the derivative stays ``-dx / sigma_j^2``). ``agreement`` (tau,
    output units): multiply by :func:`agreement_factor` (robust to neighbours from
    another part of the manifold); its derivative is included."""
    bw = np.asarray(bandwidth, dtype=np.float64)
    logw = -0.5 * (dX ** 2).sum(axis=2) / bw ** 2
    if log_factor is not None:
        logw = logw + log_factor
    if mask is not None:
        logw = np.where(mask, logw, -np.inf)
    grad = (-dX / (bw[..., None] if bw.ndim else bw) ** 2) if jacobian else None
    if agreement is not None:
        ell = Y_nb + np.einsum("nkab,nkb->nka", G_nb, dX)
        log_a, grad_a = agreement_factor(ell, logw, G_nb, agreement, jacobian)
        logw = logw + log_a
        if grad is not None:
            grad = grad + grad_a
    return jacobian_regression(dX, Y_nb, G_nb, logw, grad)


def loo_bandwidth(dX: Array, Y_nb: Array, G_nb: Array, Y: Array, grid: Array,
                  mask: NDArray[np.bool_] | None = None, log_factor: Array | None = None,
                  radius: Array | None = None, agreement: float | None = None
                  ) -> tuple[float, Array]:
    """Leave-one-out choice of the Gaussian JR bandwidth.

    ``dX``, ``Y_nb``, ``G_nb`` describe the neighbourhoods of the *training*
    points themselves with the point excluded; ``Y`` (n, dy) are the targets.
    With ``radius`` (n, k) (the neighbours' own radii), candidate ``s`` means the
    per-neighbour bandwidths ``s * radius`` (adaptive kernel).
    Returns the best bandwidth (or factor) and the LOO mean squared errors over ``grid``.
    """
    mse = np.array([((gaussian_jr(dX, Y_nb, G_nb, s if radius is None else s * radius, mask,
                                  log_factor=log_factor, agreement=agreement)[0] - Y) ** 2
                      ).sum(axis=1).mean() for s in grid])
    return float(grid[int(np.argmin(mse))]), mse


#: A chunk of leave-one-out neighbourhoods: dX, Y_nb, G_nb, Y, mask, log_factor, radius
#: (the arguments of :func:`loo_bandwidth`, for rows ``sl``).
LooChunk = tuple[Array, Array, Array, Array, Any, Any, Any]


def loo_bandwidth_chunked(n: int, chunk: Callable[[slice], LooChunk], grid: Array,
                          agreement: float | None = None, size: int = 2048
                          ) -> tuple[float, Array]:
    """:func:`loo_bandwidth` over rows gathered ``size`` at a time by ``chunk(rows)``:
    the neighbourhood arrays (n, k, dy, dx) of all n samples would take gigabytes at
    n = 100k. Same result as one call on all rows (the MSE is a sum over rows)."""
    sse = np.zeros(len(grid))
    for s in range(0, n, size):
        dX, Y_nb, G_nb, Y, mask, log_factor, radius = chunk(slice(s, min(s + size, n)))
        for i, bw in enumerate(grid):
            f = gaussian_jr(dX, Y_nb, G_nb, bw if radius is None else bw * radius, mask,
                            log_factor=log_factor, agreement=agreement)[0]
            sse[i] += ((f - Y) ** 2).sum()
    mse = sse / n
    return float(grid[int(np.argmin(mse))]), mse


class JacobianRegression(BaseEstimator):
    """Jacobian Regression with a truncated Gaussian kernel (docs/method.md §9).

    Parameters
    ----------
    n_neighbors : int, default=20
        Kernel sums run over the k nearest training inputs.
    bandwidth : float or "auto", default="auto"
        Gaussian bandwidth; "auto" = leave-one-out over ``bandwidth_grid`` times
        the median distance to the k-th neighbour.
    bandwidth_grid : tuple of float
        Relative grid for the LOO search.

    Attributes
    ----------
    bandwidth_ : float
    X_ : ndarray of shape (n, dx)
    Y_ : ndarray of shape (n, dy)
    G_ : ndarray of shape (n, dy, dx)
    """

    def __init__(self, n_neighbors: int = 20, bandwidth: float | str = "auto",
                 bandwidth_grid: tuple[float, ...] = BANDWIDTH_GRID) -> None:
        self.n_neighbors = n_neighbors
        self.bandwidth = bandwidth
        self.bandwidth_grid = bandwidth_grid

    def fit(self, X: Array, Y: Array, G: Array) -> JacobianRegression:
        """Store the sample ``X`` (n, dx), ``Y`` (n, dy) and Jacobians ``G`` (n, dy, dx)."""
        X = check_2d(X, "X")
        Y = check_2d(Y, "Y")
        G = np.asarray(G, dtype=np.float64)
        if Y.shape[0] != X.shape[0] or G.shape != (X.shape[0], Y.shape[1], X.shape[1]):
            raise ValueError(f"shapes X {X.shape}, Y {Y.shape}, G {G.shape} are inconsistent: "
                             "need G of shape (n, dy, dx)")
        self.X_, self.Y_, self.G_ = X, Y, G
        self._sqn = (X ** 2).sum(axis=1)
        k = min(self.n_neighbors, X.shape[0] - 1)
        if self.bandwidth == "auto":
            d2, ind = brute_knn(X, self._sqn, X, k + 1)
            ind, d2 = ind[:, 1:], d2[:, 1:]
            dX = X[:, None, :] - X[ind]
            grid = np.asarray(self.bandwidth_grid) * np.median(np.sqrt(d2[:, -1]))
            self.bandwidth_, self.loo_mse_ = loo_bandwidth(dX, Y[ind], G[ind], Y, grid)
        else:
            self.bandwidth_ = float(self.bandwidth)
        return self

    def predict(self, X: Array, return_jacobian: bool = False
                ) -> Array | tuple[Array, Array]:
        """f*(X) (n, dy), and optionally the exact Jacobian (n, dy, dx)."""
        check_is_fitted(self, "X_")
        X = check_2d(X, "X", self.X_.shape[1])
        _, ind = brute_knn(self.X_, self._sqn, X, self.n_neighbors)
        dX = X[:, None, :] - self.X_[ind]
        f, J, _ = gaussian_jr(dX, self.Y_[ind], self.G_[ind], self.bandwidth_,
                              jacobian=return_jacobian)
        return (f, J) if return_jacobian else f
