"""Stiefel alignment of GSE (docs/method.md §5): smooth orthonormal frame
fields ``H_i = Q_i v_i`` over local tangent bases, from a connection-Laplacian eigenproblem
with polarised links, plus the Grassmann kernels and a landmark warm start."""

from __future__ import annotations

import numpy as np
from scipy import sparse

from localization.gse.graph import (
    _CHUNK,
    Array,
    brute_knn,
    check_connected,
    knn_graph,
    polar,
    smallest_generalized_eigs,
    softmax_weights,
    symmetric_edges,
)
from localization.gse.solvers import block_matrix, connection_eigs

_KERNELS = ("binet_cauchy", "projection", "none")


def grassmann_kernel(S: Array, kind: str = "binet_cauchy") -> Array:
    """Grassmann kernel from the products ``S = Q^T Q'`` (..., q, q), values in [0, 1]."""
    if kind == "binet_cauchy":
        return np.linalg.det(S) ** 2
    if kind == "projection":
        return (S ** 2).sum(axis=(-2, -1)) / S.shape[-1]
    if kind == "none":
        return np.ones(S.shape[:-2])
    raise ValueError(f"unknown grassmann_kernel {kind!r}; choose one of {_KERNELS}")


def landmark_frames(Z: Array, Q: Array, n_landmarks: int, n_neighbors: int, kernel: str,
                    seed: int = 0) -> Array | None:
    """Coarse frame field for a warm start: align the frames of a random subsample
    (with the full-sample tangents) and extend them to every point by
    ``H_i = Q_i polar(Q_i^T sum_l K_il H_l)``. None if the subsample graph is
    disconnected."""
    n = Q.shape[0]
    lm = np.sort(np.random.default_rng(seed).permutation(n)[:n_landmarks])
    dist, ind = knn_graph(Z[lm], n_neighbors)
    sigma = 0.5 * float(np.median(dist[:, -1]))
    ei, ej = symmetric_edges(ind)
    try:
        check_connected(len(lm), ei, ej, "landmarks")
    except ValueError:
        return None
    S = _edge_products(Q[lm], ei, ej)
    K = np.exp(-0.5 * ((Z[lm][ei] - Z[lm][ej]) ** 2).sum(axis=1) / sigma ** 2)
    K = K * grassmann_kernel(S, kernel) + 1e-300
    Hl, _, _ = align_frames(Q[lm], ei, ej, K, n_refine=2, seed=seed, S=S)
    d2, nb = brute_knn(Z[lm], (Z[lm] ** 2).sum(axis=1), Z, n_neighbors)
    Qlm = Q[lm]
    H = np.empty_like(Q)
    for s in range(0, n, _CHUNK):  # (chunk, k, p, q) gathers: bounded memory (row-wise
        sl = slice(s, s + _CHUNK)  # einsums: the same numbers as one unchunked call)
        with np.errstate(divide="ignore"):
            logw = -0.5 * d2[sl] / sigma ** 2 + np.log(grassmann_kernel(
                np.einsum("npa,nkpb->nkab", Q[sl], Qlm[nb[sl]]), kernel))
        w, _ = softmax_weights(logw)
        H[sl] = Q[sl] @ polar(np.einsum("npa,nk,nkpb->nab", Q[sl], w, Hl[nb[sl]]))
    return H


def _edge_products(Q: Array, ei: Array, ej: Array) -> Array:
    """``Q_i^T Q_j`` for every edge, shape (E, q, q), in chunks."""
    q = Q.shape[2]
    if len(ei) == 0:
        return np.zeros((0, q, q))
    return np.concatenate([np.einsum("epa,epb->eab", Q[ei[s:s + 20000]], Q[ej[s:s + 20000]])
                           for s in range(0, len(ei), 20000)])


def align_frames(Q: Array, ei: Array, ej: Array, K: Array, n_refine: int = 5, seed: int = 0,
                 dense_max: int = 1500, S: Array | None = None, H0: Array | None = None,
                 lu_max: int = 6000, amg: bool = False) -> tuple[Array, Array, Array]:
    """Polarised Stiefel alignment (docs/method.md §5).

    Links ``O_ij = polar(Q_i^T Q_j)``, blocks ``A_ij = K_ij O_ij``; the smallest q
    generalized eigenvectors of ``(D - A) V = lambda D V`` give blocks ``v_i``,
    projected onto O(q); then ``n_refine`` sweeps ``H_i <- Q_i polar(Q_i^T sum_j K_ij H_j)``.
    ``amg=True`` (the scalable path): AMG-preconditioned LOBPCG
    (:func:`~localization.gse.solvers.connection_eigs`) warm-started from ``H0``.

    Returns
    -------
    H : ndarray of shape (n, p, q)
        Orthonormal frames with ``Span H_i = Span Q_i``.
    eigenvalues : ndarray of shape (q + 1,)
        The q wanted and the (q+1)-th generalized eigenvalue (gap diagnostic).
    condition : ndarray of shape (n,)
        Condition numbers of the blocks ``v_i`` before polar projection.
    """
    n, _, q = Q.shape
    if S is None:
        S = _edge_products(Q, ei, ej)
    blocks = K[:, None, None] * polar(S)
    deg = np.bincount(ei, K, n) + np.bincount(ej, K, n)
    d = np.repeat(deg, q)
    if amg:
        X0 = (np.random.default_rng(seed).standard_normal((n * q, q)) if H0 is None
              else (np.swapaxes(Q, 1, 2) @ H0).reshape(n * q, q))
        lam, V = connection_eigs(block_matrix(ei, ej, blocks, n), d, q + 1, X0, seed)
        return _finish(Q, ei, ej, K, S, V, lam, n_refine, blocks=True)
    a = np.arange(q)
    rows = (ei[:, None, None] * q + a[None, :, None]).repeat(q, axis=2)
    cols = (ej[:, None, None] * q + a[None, None, :]).repeat(q, axis=1)
    A = sparse.coo_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n * q, n * q))
    A = (A + A.T).tocsr()
    X0 = None if H0 is None else (np.swapaxes(Q, 1, 2) @ H0).reshape(n * q, q)
    lam, V = smallest_generalized_eigs(sparse.diags(d) - A, d, q + 1, seed, dense_max, lu_max, X0)
    return _finish(Q, ei, ej, K, S, V, lam, n_refine)


def _finish(Q: Array, ei: Array, ej: Array, K: Array, S: Array, V: Array, lam: Array,
            n_refine: int, blocks: bool = False) -> tuple[Array, Array, Array]:
    """Frames from the eigenvectors V (n q, >= q): polar blocks, then refinement sweeps.

    ``blocks=True`` (the scalable path) runs a sweep ``H_i <- Q_i polar(Q_i^T sum_j K_ij
    H_j)`` on the q x q blocks, since ``H_j = Q_j v_j``: ``v_i <- polar(sum_j K_ij S_ij
    v_j)`` with ``S_ij = Q_i^T Q_j`` (O(E q^3) a sweep instead of O(E p q); 73 s of a
    loaded 100k fit were the p-space sweeps). The exact path keeps the p-space sweeps:
    the same maths, but other rounding, and its results stay those of earlier releases
    (a near-degenerate eigenspace turns a rounding change into another rotation of the
    frames, harmless in theory but not for tests that replay closed loops).
    """
    n, p, q = Q.shape
    v = V[:, :q].reshape(n, q, q)
    s = np.linalg.svd(v, compute_uv=False)
    condition = s[:, 0] / np.maximum(s[:, -1], np.finfo(float).tiny)
    if blocks:
        v = polar(v)
        if n_refine:
            KS = block_matrix(ei, ej, K[:, None, None] * S, n)
            for _ in range(n_refine):
                v = polar((KS @ v.reshape(n * q, q)).reshape(n, q, q))
        return Q @ v, lam, condition
    H = Q @ polar(v)
    Ks = sparse.coo_matrix((K, (ei, ej)), shape=(n, n))
    Ks = (Ks + Ks.T).tocsr()
    for _ in range(n_refine):
        M = (Ks @ H.reshape(n, p * q)).reshape(n, p, q)
        H = Q @ polar(np.swapaxes(Q, 1, 2) @ M)
    return H, lam, condition
