"""Private numerical helpers shared by GSE and the GSE regressor.

Neighbourhood graphs, batched local PCA, polar factors, brute-force neighbour
queries (input validation: :mod:`localization.gse.validation`). Everything is
vectorised over samples; nothing
here forms an n x n or nq x nq dense matrix.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, sparse
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import lobpcg, splu
from sklearn.neighbors import NearestNeighbors

from localization.geometry import Array

_CHUNK = 1024  # rows per batch in chunked computations (bounds memory)
_REFITS = 3  # fits of fit_main_component before it gives up
T = TypeVar("T")


def polar(M: Array) -> Array:
    """Orthogonal polar factor U V^T of each matrix in a batch (..., a, b), a >= b."""
    U, _, Vt = np.linalg.svd(M, full_matrices=False)
    return U @ Vt


def knn_graph(Z: Array, n_neighbors: int) -> tuple[Array, NDArray[np.intp]]:
    """k nearest neighbours of every sample, excluding itself.

    Returns
    -------
    dist : ndarray of shape (n, k)
    ind : ndarray of shape (n, k)

    Raises ValueError naming duplicate points (zero distance to another sample).
    """
    n = Z.shape[0]
    if n_neighbors < 1 or n_neighbors >= n:
        raise ValueError(f"n_neighbors={n_neighbors} must be in [1, n_samples - 1] = [1, {n - 1}]"
                         f"; got {n} samples: use more samples or fewer neighbours")
    nn = NearestNeighbors(n_neighbors=n_neighbors + 1).fit(Z)
    dist, ind = nn.kneighbors(Z)
    scale = max(float(np.median(dist[:, -1])), np.finfo(float).tiny)
    dup = dist[:, 1] <= 1e-12 * scale
    if dup.any():
        i = np.flatnonzero(dup)
        pairs = [(int(a), int(ind[a, 0] if ind[a, 0] != a else ind[a, 1])) for a in i[:5]]
        raise ValueError(f"{dup.sum()} sample(s) duplicate another sample, e.g. index pairs {pairs}:"
                         " remove duplicate points before fitting")
    # drop self (normally column 0; robust to ties)
    keep = ind != np.arange(n)[:, None]
    keep[keep.sum(axis=1) > n_neighbors, -1] = False
    return dist[keep].reshape(n, n_neighbors), ind[keep].reshape(n, n_neighbors)


def symmetric_edges(ind: NDArray[np.intp], allowed: NDArray[np.bool_] | None = None
                    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Unique undirected edges (i < j) of the symmetrised kNN graph (A <- max(A, A^T))."""
    n, k = ind.shape
    i = np.repeat(np.arange(n), k)
    j = ind.ravel()
    if allowed is not None:
        i, j = i[allowed.ravel()], j[allowed.ravel()]
    a, b = np.minimum(i, j), np.maximum(i, j)
    key = np.unique(a.astype(np.int64) * n + b)
    return (key // n).astype(np.intp), (key % n).astype(np.intp)


class DisconnectedGraphError(ValueError):
    """The neighbourhood graph falls apart; ``labels`` (n,) gives each sample's component."""

    def __init__(self, message: str, labels: NDArray[np.intp]) -> None:
        super().__init__(message)
        self.labels = labels

    def __reduce__(self) -> tuple[type, tuple[str, NDArray[np.intp]]]:
        # picklable with its labels: it crosses process boundaries from a fit in a worker
        return type(self), (str(self), self.labels)


def check_connected(n: int, ei: NDArray[np.intp], ej: NDArray[np.intp], what: str) -> int:
    """Number of connected components; :class:`DisconnectedGraphError` (a ValueError) if
    more than one."""
    A = sparse.coo_matrix((np.ones(len(ei)), (ei, ej)), shape=(n, n)).tocsr()
    n_comp, labels = connected_components(A, directed=False)
    if n_comp > 1:
        sizes = np.bincount(labels)
        raise DisconnectedGraphError(
            f"the neighbourhood graph of {what} has {n_comp} connected components (sizes "
            f"{sorted(sizes.tolist(), reverse=True)[:10]}): GSE would place them arbitrarily. "
            "Increase n_neighbors (or bandwidth), or fit one model per component.", labels)
    return int(n_comp)


def fit_main_component(fit: Callable[[NDArray[np.intp]], T], n: int, max_dropped: float,
                       what: str = "the training samples") -> tuple[T, NDArray[np.intp]]:
    """``fit(index)`` on the samples ``index`` of ``n``; where their neighbourhood graph falls
    apart (:class:`DisconnectedGraphError`), again on the largest component alone, as long as
    at most ``max_dropped`` of the ``n`` samples are dropped (a RuntimeWarning says how many).

    Returns
    -------
    fitted : what ``fit`` returned
    kept : ndarray of shape (n_kept,) — the indices it was fitted on, ascending

    Raises
    ------
    DisconnectedGraphError
        If keeping the largest component would drop more than ``max_dropped`` (message and
        labels of the last fit), or the graph still falls apart after a few refits.
    """
    index = np.arange(n)
    for attempt in range(_REFITS):
        try:
            fitted = fit(index)
        except DisconnectedGraphError as err:
            main = err.labels == np.argmax(np.bincount(err.labels))
            if attempt == _REFITS - 1 or n - main.sum() > max_dropped * n:
                raise
            index = index[main]
            continue
        if len(index) < n:
            warnings.warn(f"{n - len(index)} of {n} samples of {what} were cut off from the "
                          "rest of GSE's neighbourhood graph and were dropped", RuntimeWarning,
                          stacklevel=3)
        return fitted, index
    raise AssertionError("unreachable")  # the last attempt returns or raises


def local_pca(Z: Array, centers: Array, nbr: Array, weights: Array, q: int) -> Array:
    """Weighted local PCA tangent bases, never forming p x p matrices.

    Parameters
    ----------
    Z : ndarray of shape (n, p)
        Sample.
    centers : ndarray of shape (n_c, p)
        Points at which to estimate the tangent space.
    nbr : ndarray of shape (n_c, k)
        Neighbour indices into ``Z``.
    weights : ndarray of shape (n_c, k)
        Kernel weights (non-negative).
    q : int

    Returns
    -------
    Q : ndarray of shape (n_c, p, q)
        Orthonormal bases: top-q right singular vectors of the k x p matrix with
        rows ``sqrt(w_j) (Z_j - center)``.
    """
    n_c, p = centers.shape
    Q = np.empty((n_c, p, q))
    for s in range(0, n_c, _CHUNK):
        sl = slice(s, s + _CHUNK)
        D = (Z[nbr[sl]] - centers[sl, None, :]) * np.sqrt(weights[sl])[:, :, None]
        _, _, Vt = np.linalg.svd(D, full_matrices=False)
        Q[sl] = np.swapaxes(Vt[:, :q, :], 1, 2)
    return Q


def brute_knn(X: Array, sqnorm: Array, Xq: Array, k: int) -> tuple[Array, NDArray[np.intp]]:
    """k nearest rows of ``X`` for each row of ``Xq``, sorted by distance.

    Candidates come from a GEMM; the returned squared distances are recomputed
    exactly from differences, so results are sample-wise (a row gives the same
    answer alone or in a batch, barring exact ties).
    """
    n = X.shape[0]
    k = min(k, n)
    D2 = np.empty((Xq.shape[0], k))
    ind = np.empty((Xq.shape[0], k), dtype=np.intp)
    for s in range(0, Xq.shape[0], _CHUNK):
        xq = Xq[s:s + _CHUNK]
        d2 = sqnorm[None, :] - 2.0 * xq @ X.T
        if k < n:
            cand = np.argpartition(d2, k - 1, axis=1)[:, :k]
        else:
            cand = np.broadcast_to(np.arange(n), d2.shape).copy()
        exact = ((X[cand] - xq[:, None, :]) ** 2).sum(axis=2)
        order = np.argsort(exact, axis=1, kind="stable")
        ind[s:s + _CHUNK] = np.take_along_axis(cand, order, axis=1)
        D2[s:s + _CHUNK] = np.take_along_axis(exact, order, axis=1)
    return D2, ind


def same_side(cut_nb: Array) -> NDArray[np.bool_]:
    """Mask of neighbours on the same side of every cut at +-pi as the nearest one.

    ``cut_nb`` (n, k) or (n, k, c): the periodic cut coordinates (radians, in (-pi, pi])
    of each neighbour, nearest first. A neighbour is kept when, for every cut, the
    unwrapped difference to the nearest neighbour is at most pi (the segment between
    them does not cross the cut).
    """
    keep = np.abs(cut_nb - cut_nb[:, :1]) <= np.pi
    return keep if keep.ndim == 2 else keep.all(axis=2)


def loop_coordinate(X: Array, n_neighbors: int = 10, seed: int = 0, min_radius: float = 0.5,
                    max_ratio: float = 2.0) -> Array | None:
    """Angle along a closed loop traced by the sample, or None if it is not a loop.

    The first two non-trivial eigenvectors of the random-walk Laplacian of the
    (unweighted, symmetrised) kNN graph of a sample along a closed curve (or a thin tube around one) are a cosine / sine pair
    of the position along the curve, so ``atan2(v2, v1)`` is a monotone loop angle.
    On a disc-like sample the same pair passes through the origin (e.g.
    ``cos(pi x), cos(pi y)`` on a square), and on an open path the pair is
    ``cos(pi t), cos(2 pi t)`` with eigenvalues in ratio ~4. Loop test: the two
    eigenvalues differ by less than ``max_ratio`` and the 1st percentile of the radius
    ``|(v1, v2)|`` is at least ``min_radius`` x its median.

    Parameters
    ----------
    X : ndarray of shape (n, d)
        Low-dimensional coordinates (e.g. positions in metres).
    n_neighbors : int, default=10
    seed : int, default=0
    min_radius : float, default=0.5
    max_ratio : float, default=2.0

    Returns
    -------
    angle : ndarray of shape (n,) in (-pi, pi], or None
    """
    X, inverse = np.unique(X, axis=0, return_inverse=True)  # e.g. one position, many headings
    inverse = inverse.ravel()
    n = X.shape[0]
    if n < 4 * n_neighbors:
        return None
    _, ind = knn_graph(X, n_neighbors)
    ei, ej = symmetric_edges(ind)
    if connected_components(sparse.coo_matrix((np.ones(len(ei)), (ei, ej)), shape=(n, n)),
                            directed=False)[0] > 1:
        return None
    # unweighted links: Gaussian weights would make a sparse stretch of the loop a weak
    # link, and the eigenvector pair then localises instead of going round
    A = sparse.coo_matrix((np.ones(len(ei)), (ei, ej)), shape=(n, n))
    A = (A + A.T).tocsr()
    deg = np.asarray(A.sum(axis=1)).ravel()
    # shift-invert with one sparse LU at any size: a planar kNN graph factorises cheaply,
    # and LOBPCG from a random start misses the near-degenerate pair (n = 10000)
    lam, V = smallest_generalized_eigs((sparse.diags(deg) - A).tocsr(), deg, 3, seed,
                                       lu_max=10 ** 7)
    if not lam[2] < max_ratio * lam[1]:  # a path has lambda_2 ~ 4 lambda_1, a loop a pair
        return None
    r = np.hypot(V[:, 1], V[:, 2])
    if np.percentile(r, 1) < min_radius * np.median(r):
        return None
    return np.arctan2(V[:, 2], V[:, 1])[inverse]


def cuts_keep_connected(X: Array, cut: Array, n_neighbors: int) -> bool:
    """Whether the kNN graph of ``X`` (n, d) stays connected once the links crossing any
    of the cuts ``cut`` (n, c) (angles, see :func:`same_side`) are removed."""
    n = X.shape[0]
    _, ind = knn_graph(X, n_neighbors)
    allowed = same_side(np.concatenate([cut[:, None, :], cut[ind]], axis=1))[:, 1:]
    ei, ej = symmetric_edges(ind, allowed)
    A = sparse.coo_matrix((np.ones(len(ei)), (ei, ej)), shape=(n, n))
    return connected_components(A, directed=False)[0] == 1


def softmax_weights(logw: Array) -> tuple[Array, Array]:
    """Normalised weights from log-weights (n, k) and log of the kernel sum (n,)."""
    mx = logw.max(axis=1, keepdims=True)
    e = np.exp(logw - mx)
    s = e.sum(axis=1, keepdims=True)
    return e / s, (mx + np.log(s))[:, 0]


def smallest_generalized_eigs(M: sparse.spmatrix, d: Array, nev: int, seed: int = 0,
                              dense_max: int = 1500, lu_max: int = 6000,
                              X0: Array | None = None, tol: float = 1e-7, maxiter: int = 100
                              ) -> tuple[Array, Array]:
    """Smallest ``nev`` eigenpairs of ``M v = lambda diag(d) v`` (M sparse PSD, d > 0).

    Size N <= ``dense_max``: dense ``eigh``. N <= ``lu_max``: block shift-invert
    subspace iteration with Rayleigh-Ritz (one sparse LU; handles exactly
    degenerate eigenvalues). Larger: LOBPCG on ``D^-1/2 (D - M) D^-1/2`` (largest),
    started from ``X0`` (N, <=nev) if given, completed by seeded random columns.
    Returns eigenvalues (nev,) and D-orthonormal eigenvectors (N, nev).
    """
    N = M.shape[0]
    rng = np.random.default_rng(seed)
    if N <= dense_max:
        return linalg.eigh(M.toarray(), np.diag(d), subset_by_index=[0, nev - 1])
    if N <= lu_max:
        lu = splu(sparse.csc_matrix(M + 1e-5 * sparse.diags(d)), permc_spec="MMD_AT_PLUS_A")
        X = rng.standard_normal((N, nev + 4))
        for _ in range(maxiter):
            X = np.column_stack([lu.solve(c) for c in (d[:, None] * X).T])
            MX = M @ X
            lam, C = linalg.eigh(X.T @ MX, X.T @ (d[:, None] * X))
            X, MX = X @ C, MX @ C
            R = MX[:, :nev] - d[:, None] * X[:, :nev] * lam[:nev]
            res = np.linalg.norm(R, axis=0) / np.linalg.norm(d[:, None] * X[:, :nev], axis=0)
            if res[:-1].max() < tol and res[-1] < 1e-4:  # the last pair is a gap diagnostic
                break
        return lam[:nev], X[:, :nev]
    isq = 1.0 / np.sqrt(d)
    Nop = (sparse.diags(isq) @ (sparse.diags(d) - M) @ sparse.diags(isq)).tocsr()
    X = rng.standard_normal((N, nev + 2))
    if X0 is not None:
        X[:, :X0.shape[1]] = X0 * np.sqrt(d)[:, None]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "did not reach tolerance": checked below
        mu, X = lobpcg(Nop, X, largest=True, tol=1e-6, maxiter=maxiter)
    order = np.argsort(-mu)[:nev]
    mu, X = mu[order], X[:, order]
    res = np.linalg.norm(Nop @ X[:, :-1] - X[:, :-1] * mu[:-1], axis=0)
    if res.max() > 1e-4:
        warnings.warn(f"alignment eigensolver (LOBPCG) residual {res.max():.2g} > 1e-4 after "
                      f"{maxiter} iterations", RuntimeWarning, stacklevel=3)
    return 1.0 - mu, X * isq[:, None]


def pinv_blocks(H: Array, ridge: float = 0.0) -> Array:
    """``(H^T H + ridge I)^{-1} H^T`` for a batch (n, a, b) -> (n, b, a), by q x q solves."""
    HtH = np.swapaxes(H, 1, 2) @ H + ridge * np.eye(H.shape[2])
    try:
        return np.linalg.solve(HtH, np.swapaxes(H, 1, 2))
    except np.linalg.LinAlgError:  # an exactly rank-deficient block (only with ridge=0)
        warnings.warn("a block of the GSE frames is rank-deficient (the poses or features do "
                      "not vary along the fitted manifold at some samples); using the "
                      "minimum-norm pseudo-inverse there: pass ridge > 0 to regularise",
                      RuntimeWarning, stacklevel=3)
        return np.linalg.pinv(H)
