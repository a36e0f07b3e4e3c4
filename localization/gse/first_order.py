"""First-order terms of r* from the forward model w(theta) (docs/method.md §8.5).

r*(w) is a Jacobian Regression (docs/method.md §9)::

    r*(w) = sum_j K(w, w_j) [y_j + G_j (w - w_j)] / sum_j K(w, w_j)

and the feature-space neighbours of a query are spread over the pose space (on a lane
map, a median 0.13 m across the lane): the first-order terms ``G_j (w - w_j)`` are what
moves r* from their kernel average to the query. By default ``G_j`` is the pseudo-inverse
of the feature block of GSE's recovery Jacobian (``first_order="frames"``). With
``first_order="forward"`` it comes from the *forward* model instead, the features as a
function of the pose, which the training poses pin down without error:

    w_i - w_j = B_j (theta_i - theta_j) + c_j + e_ij       (least squares over the K pose-space
                                                             neighbours i of sample j; B_j (m, d))
    S   = sum e e^T / (n (K - d - 1)),   S <- (1 - lam) S + lam tr(S)/m I
    G_j = GR_j (B_j^T S^-1 B_j)^-1 B_j^T S^-1                (the generalised least-squares left inverse)

``GR_j`` (q, d) is the pose-to-representation Jacobian R* already uses, so ``G_j B_j = GR_j``:
a feature change the pose explains moves r* as the pose would, and the directions in which
the features vary most without the pose (S, their residual covariance) count least (the
Gauss-Markov estimator of the pose change behind a feature change). With ``ridge`` > 0
(``GSERegressor(forward_ridge=...)``) the inverse is ``(I_j + rho_j 1)^-1 B_j^T S^-1``,
``I_j = B_j^T S^-1 B_j``, ``rho_j = ridge tr(I_j) / d``: the pose directions a sample's
features barely see pass less feature noise on (docs/method.md §8.5). Pose differences are the
scaled ones of ``_pose_diff`` (angles wrapped), so the cuts do not matter here.

Measured on the appearance benchmark's daylight maps of tuning cities 11-12 (15000
route-lane images, PixelPCA(128, patches), 300 test images per look): psi*'s slope of the
predicted on the true offset across the lane 0.37-0.43 -> 0.52-0.56 in daylight, images within
(0.25 m, 2 deg) default 77-78 -> 82-84 %, overcast 75-76 -> 82 %, dusk 67-74 -> 73-76 %,
night 61-63 -> 60-63 % (K = 20, lam = 0.1; K = 10, 15, 30, 50 and lam = 0, 0.3 were tried).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.linalg import pinvh
from sklearn.covariance import shrunk_covariance

from localization.gse.graph import Array

__all__ = ["FIRST_ORDER", "FORWARD_NEIGHBORS", "FORWARD_SHRINKAGE", "forward_gls_jacobians",
           "forward_tangents", "gls_left_inverse", "shrunk_precision"]

#: The choices of ``GSERegressor(first_order=...)``.
FIRST_ORDER = ("frames", "forward")
#: Pose-space neighbours of each sample in the forward regression (tuning cities 11-12).
FORWARD_NEIGHBORS = 20
#: Shrinkage of the residual covariance towards its mean variance (tuning cities 11-12).
FORWARD_SHRINKAGE = 0.1
#: Rows per chunk: the neighbourhoods (rows, K, m) of 100k samples would take gigabytes.
CHUNK = 2048


def forward_tangents(dTheta: Array, dW: Array) -> tuple[Array, Array]:
    """Local affine fits of feature differences on pose differences.

    Parameters
    ----------
    dTheta : ndarray (n, K, d)
        Pose differences ``theta_i - theta_j`` of each sample's K neighbours (scaled).
    dW : ndarray (n, K, m)
        The matching feature differences ``w_i - w_j``.

    Returns
    -------
    B : ndarray (n, m, d)
        ``dw/dtheta`` at each sample.
    residuals : ndarray (n, K, m)
        ``dW`` minus the fit (an intercept absorbs the curvature's mean).
    """
    n, k, d = dTheta.shape
    if k < d + 2:
        raise ValueError(f"the forward fit needs at least d + 2 = {d + 2} neighbours, got {k}")
    A = np.concatenate([dTheta, np.ones((n, k, 1))], axis=2)
    AtA = np.einsum("nki,nkj->nij", A, A) + 1e-12 * np.eye(d + 1)
    coef = np.linalg.solve(AtA, np.einsum("nki,nkm->nim", A, dW))  # (n, d + 1, m)
    residuals = dW - np.einsum("nki,nim->nkm", A, coef)
    return np.swapaxes(coef[:, :d, :], 1, 2), residuals


def shrunk_precision(scatter: Array, dof: float, shrinkage: float) -> Array:
    """Inverse of the residual covariance ``scatter / dof`` shrunk towards its mean variance,
    ``S = (1 - shrinkage) S + shrinkage tr(S)/m I`` (scikit-learn's ``shrunk_covariance``),
    (m, m); a pseudo-inverse (``scipy.linalg.pinvh``) if S is singular."""
    if not dof > 0:
        raise ValueError(f"no residual degrees of freedom for the forward fit (dof={dof})")
    return pinvh(shrunk_covariance(scatter / dof, shrinkage))


def gls_left_inverse(B: Array, precision: Array, ridge: float = 0.0) -> Array:
    """``(I + rho I_d)^-1 B^T P`` (n, d, m) with ``I = B^T P B`` for tangents B (n, m, d)
    and precision P (m, m); ``rho = ridge tr(I) / d`` per sample damps the pose directions
    the features see least, relative to that sample's mean information (0: the plain
    generalised least-squares inverse); a pseudo-inverse where the matrix is singular (a
    pose direction the features never see)."""
    BtP = np.swapaxes(B, 1, 2) @ precision
    info = BtP @ B
    d = info.shape[-1]
    if ridge > 0:
        rho = ridge * np.trace(info, axis1=1, axis2=2) / d
        info = info + rho[:, None, None] * np.eye(d)
    return np.linalg.pinv(info, hermitian=True) @ BtP


def forward_gls_jacobians(Ws: Array, GR: Array, neighbors: Callable[[Array], Array],
                          pose_diff: Callable[[Array, Array], Array], rows: Array,
                          shrinkage: float = FORWARD_SHRINKAGE,
                          precision: Array | None = None, ridge: float = 0.0
                          ) -> tuple[Array, Array]:
    """``G_j = GR_j (B_j^T P B_j + rho_j 1)^-1 B_j^T P`` for the samples ``rows`` (see the
    module docstring; ``rho_j = 0`` without ``ridge``), in chunks.

    Parameters
    ----------
    Ws : ndarray (n, m)
        Standardised features of all samples.
    GR : ndarray (n, q, d)
        Pose-to-representation Jacobians of all samples (per scaled pose unit).
    neighbors : callable
        ``neighbors(rows)`` -> (len(rows), K) indices of each row's K nearest other samples
        in pose space.
    pose_diff : callable
        ``pose_diff(rows, ind)`` -> scaled pose differences ``theta_ind - theta_rows``
        (len(rows), K, d), angles wrapped.
    rows : ndarray of int
        The samples whose G is wanted.
    shrinkage : float
        The covariance's shrinkage towards its mean variance.
    precision : ndarray (m, m), optional
        The residual precision P to use (e.g. the fitted one, when ``partial_fit`` adds
        samples); None estimates it from the residuals of ``rows``.
    ridge : float
        The damping of weak pose directions in the inverse (:func:`gls_left_inverse`).

    Returns
    -------
    G : ndarray (len(rows), q, m)
    precision : ndarray (m, m)
    """
    rows = np.asarray(rows, dtype=np.intp)
    m, d = Ws.shape[1], GR.shape[2]
    B = np.empty((len(rows), m, d))
    scatter, dof = np.zeros((m, m)), 0.0
    for s in range(0, len(rows), CHUNK):
        r = rows[s:s + CHUNK]
        ind = neighbors(r)
        B[s:s + len(r)], res = forward_tangents(pose_diff(r, ind), Ws[ind] - Ws[r, None, :])
        if precision is None:
            flat = res.reshape(-1, m)
            scatter += flat.T @ flat
            dof += len(r) * (ind.shape[1] - d - 1)
    if precision is None:
        precision = shrunk_precision(scatter, dof, shrinkage)
    G = np.empty((len(rows), GR.shape[1], m))
    for s in range(0, len(rows), CHUNK):
        G[s:s + CHUNK] = GR[rows[s:s + CHUNK]] @ gls_left_inverse(B[s:s + CHUNK], precision,
                                                                  ridge)
    return G, precision
