"""Incremental GSE: add samples to a fitted embedding without a refit (docs/method.md §18).

The update is local. With ``U`` = the new samples plus the old samples whose k nearest
neighbours change (a new sample comes closer than their k-th neighbour):

1. neighbours: each new sample gets its k nearest among all samples; each old sample in
   ``U`` merges the new candidates into its list (exact distances; on the exact path a
   brute force against every old sample, so the graph equals the kNN graph of the union;
   on the approximate path the old samples checked are the 2k nearest of each new one,
   found with the HNSW index);
2. tangents ``Q_i`` (local PCA with the kept bandwidth) are recomputed on ``U``;
3. frames: old samples in ``U`` re-project their frame onto the new tangent,
   ``H_i = Q_i polar(Q_i^T H_i)``; new samples are aligned greedily outward from the
   samples with frames (docs/method.md §5, the greedy variant), then ``n_refine``
   sweeps ``H_i <- Q_i polar(Q_i^T sum_j K_ij H_j)`` run over ``U`` with every other
   frame held fixed;
4. embedding: the least-squares energy of docs/method.md §6 restricted to the edges that
   touch ``U``, with every other ``y_j`` held fixed (a Dirichlet problem on ``U``,
   one sparse factorisation of size |U|).

Everything else is kept: the bandwidths, the standardisation, the pose scale and the
frames and coordinates of the samples outside ``U``. The cost is O(n_new n p) for the
neighbour search on the exact path (a BLAS brute force against the old samples), O(n_new
log n) with the HNSW index of the approximate path, plus O(|U| k p q) for the local work
and O(n log n) for the pose-space radii (a 4-D KD-tree); no global solve.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.sparse.linalg import splu

from localization.gse.alignment import grassmann_kernel
from localization.gse.graph import Array, brute_knn, local_pca, pinv_blocks, polar, same_side

__all__ = ["add_regression_samples", "add_samples", "check_cut"]


def check_cut(cut: Array, n: int, n_cuts: int | None = None) -> Array:
    """Cut coordinates as finite angles of shape (n, c) (from (n,) or (n, c)); ValueError
    naming ``cut`` otherwise (``n_cuts``: the c of the fit, for partial_fit)."""
    c = np.asarray(cut, dtype=np.float64)
    c = c[:, None] if c.ndim == 1 else c
    want = f"({n}, {n_cuts})" if n_cuts else f"({n},) or ({n}, c)"
    if (c.ndim != 2 or c.shape[0] != n or (n_cuts and c.shape[1] != n_cuts)
            or not np.isfinite(c).all()):
        raise ValueError(f"cut must be {n} finite angles per cut (shape {want}), got shape "
                         f"{np.shape(cut)}")
    return c


def _check_duplicates(d2: Array, scale: float, name: str) -> None:
    dup = np.sqrt(d2[:, 0]) <= 1e-12 * scale
    if dup.any():
        raise ValueError(f"{name}: {dup.sum()} new sample(s) duplicate a sample of the model, "
                         f"first new row {int(np.flatnonzero(dup)[0])}: remove duplicates")


def _new_neighbors(gse: Any, Z: Array, n0: int, k: int, name: str
                   ) -> tuple[Array, NDArray[np.intp]]:
    """k nearest samples (distances, indices) of each new row among all n rows: among the
    old rows by a BLAS brute force (exact path) or the model's HNSW index (approximate
    path; it gets the new rows only once the update has succeeded), among the new rows
    by brute force; exact distances."""
    Z_new = Z[n0:]
    if getattr(gse, "_index", None) is not None:
        d2o, io = gse._index.query(Z_new, k)
    else:
        d2o, io = brute_knn(Z[:n0], (Z[:n0] ** 2).sum(axis=1), Z_new, k)
    d2n, in_ = brute_knn(Z_new, (Z_new ** 2).sum(axis=1), Z_new, min(k + 1, len(Z_new)))
    d2n[in_ == np.arange(len(Z_new))[:, None]] = np.inf  # the row itself
    d2 = np.concatenate([d2o, d2n], axis=1)
    ind = np.concatenate([io, n0 + in_], axis=1)
    order = np.argsort(d2, axis=1, kind="stable")[:, :k]
    d2, ind = np.take_along_axis(d2, order, axis=1), np.take_along_axis(ind, order, axis=1)
    _check_duplicates(d2, float(np.median(gse.neighbor_distances_[:, -1])), name)
    return np.sqrt(d2), ind


def _candidate_rows(index: Any, X_new: Array, k: int) -> NDArray[np.intp] | None:
    """Old rows that may have a new row among their k nearest: with an HNSW index, the 2k
    nearest old rows of every new row (kNN is nearly symmetric on a manifold sample);
    None (all rows, exact) without one."""
    if index is None:
        return None
    return np.unique(index.query(X_new, 2 * k)[1])


def _close_rows(X: Array, rows: NDArray[np.intp] | None, X_new: Array, radius: Array
                ) -> tuple[NDArray[np.intp], list[Array]]:
    """The old rows (of ``rows``, or all) with a new row closer than their ``radius``,
    and the squared distances (n_new, .) blocks of those rows (GEMM, bounded memory)."""
    rows = np.arange(len(radius)) if rows is None else rows
    sq = (X_new ** 2).sum(axis=1)
    size = max(256, 2 ** 23 // len(X_new))  # (n_new, size) blocks: <= 64 MiB
    hits, blocks = [], []
    for s in range(0, len(rows), size):
        r = rows[s:s + size]
        xo = X[r]
        d2 = np.maximum(sq[:, None] - 2.0 * X_new @ xo.T + (xo ** 2).sum(axis=1), 0.0)
        # GEMM distances lose ~1e-12 relative: a margin, the exact merge decides
        hit = np.flatnonzero((d2 < radius[r] ** 2 * (1 + 1e-8)).any(axis=0))
        hits.append(r[hit])
        blocks.append(d2[:, hit])
    return (np.concatenate(hits) if hits else np.zeros(0, dtype=np.intp)), blocks


def _merge_old(gse: Any, Z: Array, n0: int, k: int) -> tuple[NDArray[np.intp], Array, Array]:
    """Old rows whose kNN list gains a new sample, with their merged lists."""
    ind, dist = gse.neighbors_, gse.neighbor_distances_
    Z_new = Z[n0:]
    cand_rows = _candidate_rows(getattr(gse, "_index", None), Z_new, k)
    hit, blocks = _close_rows(Z, cand_rows, Z_new, dist[:, -1])
    if not hit.size:
        return hit, np.zeros((0, k), dtype=np.intp), np.zeros((0, k))
    d2 = np.concatenate(blocks, axis=1).T  # (hits, n_new)
    kk = min(k, len(Z_new))
    top = np.argpartition(d2, kk - 1, axis=1)[:, :kk]  # new candidates
    cand = np.concatenate([ind[hit], n0 + top], axis=1)
    exact = np.sqrt(((Z[cand] - Z[hit][:, None, :]) ** 2).sum(axis=2))
    order = np.argsort(exact, axis=1, kind="stable")[:, :k]
    return (hit, np.take_along_axis(cand, order, axis=1),
            np.take_along_axis(exact, order, axis=1))


def _local_edges(ind: NDArray[np.intp], U: NDArray[np.intp], cut: Array | None
                 ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Undirected edges (i < j) of the symmetrised kNN graph with an end in ``U``."""
    n, k = ind.shape
    inU = np.zeros(n, dtype=bool)
    inU[U] = True
    rows = np.flatnonzero(inU | inU[ind].any(axis=1))
    i = np.repeat(rows, k)
    j = ind[rows].ravel()
    if cut is not None:
        allowed = same_side(np.concatenate([cut[rows, None, :], cut[ind[rows]]], axis=1))[:, 1:]
        i, j = i[allowed.ravel()], j[allowed.ravel()]
    touch = inU[i] | inU[j]
    a, b = np.minimum(i[touch], j[touch]), np.maximum(i[touch], j[touch])
    key = np.unique(a.astype(np.int64) * n + b)
    return (key // n).astype(np.intp), (key % n).astype(np.intp)


def _kernel(gse: Any, Z: Array, Q: Array, ei: Array, ej: Array) -> Array:
    """Aggregate kernel K_ij (Euclidean heat kernel x Grassmann kernel) on edges."""
    S = np.swapaxes(Q[ei], 1, 2) @ Q[ej]
    KG = grassmann_kernel(S, gse.grassmann_kernel)
    if gse.grassmann_threshold is not None:
        KG = np.where(np.sqrt(np.clip(1 - np.linalg.det(S) ** 2, 0, 1))
                      < gse.grassmann_threshold, KG, 0.0)
    return np.exp(-0.5 * ((Z[ei] - Z[ej]) ** 2).sum(axis=1) / gse.bandwidth_ ** 2) * KG


def _frames(gse: Any, Q: Array, H: Array, U: Array, new: Array, ei: Array, ej: Array,
            K: Array, name: str) -> None:
    """Greedy alignment of the new frames, then refinement sweeps over U (in place)."""
    n, p, q = Q.shape
    Ks = sparse.coo_matrix((K, (ei, ej)), shape=(n, n))
    Ks = (Ks + Ks.T).tocsr()
    known = np.ones(n, dtype=bool)
    known[new] = False
    H[new] = 0.0
    todo = new
    while todo.size:  # breadth-first from the samples with frames
        Kt = Ks[todo]
        reach = np.asarray(Kt @ known.astype(float)).ravel() > 0
        if not reach.any():
            raise ValueError(f"{name}: {todo.size} new sample(s) have no kernel link to the "
                             "fitted samples (another component): refit on the union instead")
        rows = todo[reach]
        M = (Ks[rows] @ H.reshape(n, p * q)).reshape(-1, p, q)  # unknown frames are 0
        H[rows] = Q[rows] @ polar(np.swapaxes(Q[rows], 1, 2) @ M)
        known[rows] = True
        todo = todo[~reach]
    KU = Ks[U]
    for _ in range(gse.n_refine):
        M = (KU @ H.reshape(n, p * q)).reshape(-1, p, q)
        H[U] = Q[U] @ polar(np.swapaxes(Q[U], 1, 2) @ M)


def _embed(Z: Array, H: Array, Y: Array, U: Array, ei: Array, ej: Array, K: Array) -> None:
    """Coordinates of U minimising the energy of docs/method.md §6 on the edges touching
    U, the others fixed (in place)."""
    n, q = Y.shape
    b = 0.5 * (((H[ei] + H[ej]) * (Z[ei] - Z[ej])[:, :, None]).sum(axis=1))  # (E, q)
    Ks = sparse.coo_matrix((K, (ei, ej)), shape=(n, n))
    Ks = (Ks + Ks.T).tocsr()
    deg = np.asarray(Ks.sum(axis=1)).ravel()
    B = np.zeros((n, q))
    np.add.at(B, ei, K[:, None] * b)
    np.add.at(B, ej, -K[:, None] * b)
    fixed = np.ones(n, dtype=bool)
    fixed[U] = False
    KU = Ks[U]
    rhs = B[U] + KU[:, fixed] @ Y[fixed]
    L = (sparse.diags(deg[U]) - KU[:, U]).tocsc()
    Y[U] = splu(L).solve(rhs)


def add_samples(gse: Any, Z_new: Array, cut_new: Array | None, name: str) -> NDArray[np.intp]:
    """Add rows ``Z_new`` (n_new, p) (and their cut coordinates (n_new, c)) to a fitted
    :class:`~localization.gse.embedding.GrassmannStiefelEigenmaps` in place.

    Returns the indices of the rows whose tangent, frame or coordinates changed (the new
    rows and the old rows ``U`` of the module docstring), ascending.
    """
    n0, k, q = len(gse.Z_), gse.n_neighbors, gse.n_components
    Z = np.ascontiguousarray(np.vstack([gse.Z_, Z_new]))
    n = len(Z)
    dist_new, ind_new = _new_neighbors(gse, Z, n0, k, name)
    rows, lists, dists = _merge_old(gse, Z, n0, k)
    ind = np.vstack([gse.neighbors_, ind_new])
    dist = np.vstack([gse.neighbor_distances_, dist_new])
    ind[rows], dist[rows] = lists, dists
    cut = None if gse.cut_ is None else np.vstack([gse.cut_, cut_new])
    new = np.arange(n0, n)
    U = np.concatenate([rows, new])
    old_ei, _ = _local_edges(gse.neighbors_, rows, gse.cut_)
    Q = np.concatenate([gse.tangents_, np.empty((len(new), *gse.tangents_.shape[1:]))])
    Q[U] = local_pca(Z, Z[U], ind[U], np.exp(-0.5 * (dist[U] / gse.bandwidth_) ** 2), q)
    H = np.concatenate([gse.frames_, np.empty_like(Q[new])])
    H[rows] = Q[rows] @ polar(np.swapaxes(Q[rows], 1, 2) @ gse.frames_[rows])
    ei, ej = _local_edges(ind, U, cut)
    K = _kernel(gse, Z, Q, ei, ej)
    live = K > 1e-300
    ei, ej, K = ei[live], ej[live], K[live]
    _frames(gse, Q, H, U, new, ei, ej, K, name)
    Y = np.concatenate([gse.embedding_, np.zeros((len(new), q))])
    _embed(Z, H, Y, U, ei, ej, K)
    gse.n_edges_ = int(gse.n_edges_ - len(old_ei) + len(ei))
    gse.Z_, gse.tangents_, gse.frames_, gse.embedding_ = Z, Q, H, Y
    gse.neighbors_, gse.neighbor_distances_, gse.cut_ = ind, dist, cut
    gse.frame_condition_ = np.concatenate([gse.frame_condition_, np.full(len(new), np.nan)])
    return np.sort(U)


def add_regression_samples(model: Any, W_new: Array, Theta_new: Array) -> Any:
    """:meth:`GSERegressor.partial_fit <localization.gse.regressor.GSERegressor.partial_fit>`:
    validate, lift the new poses with the kept scale, add the joint vectors to the GSE
    (:func:`add_samples`) and recompute the per-sample Jacobians ``G_r``, ``G_R`` and radii
    on the rows that changed."""
    from localization.geometry import wrap_angle
    from localization.gse.validation import validate_X, validate_y

    W = validate_X(model, W_new, "W", reset=False)
    Theta, is_1d = validate_y(model, Theta_new, len(W), "y", "W")
    d, m, n0 = len(model.theta_scale_), len(model.w_mean_), len(model.theta_)
    if Theta.shape[1] != d or is_1d != bool(getattr(model, "y_1d_", False)):
        raise ValueError(f"y has shape {np.shape(Theta_new)}: the model was fitted on "
                         f"poses of shape (n, {d})" + (" given as a 1-D array" if
                                                        getattr(model, "y_1d_", False) else "")
                         + " (the same pose layout is needed)")
    Theta = Theta.copy()
    for c in model._per:
        Theta[:, c] = wrap_angle(Theta[:, c])
    Ws = (W - model.w_mean_) / model.w_scale_
    cuts = [Theta[:, c] for c in model._per]
    if model.loop_angle_ is not None:  # the loop angle of the nearest training position
        from scipy.spatial import cKDTree

        lin = [c for c in range(d) if c not in model._per]
        near = cKDTree(model.theta_[:, lin]).query(Theta[:, lin])[1]
        cuts.append(model.loop_angle_[near])
    w_hits, _ = _close_rows(model._ws, _candidate_rows(getattr(model, "_ws_index", None), Ws,
                                                        model.jr_neighbors_),
                            Ws, model.w_radius_)
    model.gse_._add(np.column_stack([Ws, model._lift(Theta)]),
                    np.column_stack(cuts) if cuts else None, "W")
    g = model.gse_
    n = len(g.Z_)
    changed = np.union1d(g.partial_fit_rows_, w_hits)
    model.theta_ = np.vstack([model.theta_, Theta])
    model.cut_ = g.cut_
    if model.loop_angle_ is not None:
        model.loop_angle_ = np.concatenate([model.loop_angle_, cuts[-1]])

    def grow(a: Array) -> Array:
        return np.concatenate([a, np.zeros((n - n0, *a.shape[1:]))])

    model.Gr_, model.GR_ = grow(model.Gr_), grow(model.GR_)
    model.pose_condition_, model._w_tangents = grow(model.pose_condition_), grow(model._w_tangents)
    model.w_radius_ = grow(model.w_radius_)
    H = g.frames_[changed]
    model._w_tangents[changed] = np.linalg.qr(H[:, :m, :])[0]
    Hv = H[:, m:, :]
    model.GR_[changed] = pinv_blocks(Hv, model.ridge) @ model._dlift(model.theta_[changed])
    s = np.linalg.svd(Hv, compute_uv=False)
    model.pose_condition_[changed] = s[:, 0] / np.maximum(s[:, -1], np.finfo(float).tiny)
    model._setup()  # query structures of the union (the HNSW index grows by insertion)
    moved = np.concatenate([w_hits, np.arange(n0, n)])  # feature-space neighbours changed
    d2, _ = model._query_w(model._ws[moved], model.jr_neighbors_ + 1)
    model.w_radius_[moved] = np.sqrt(d2[:, -1])  # column 0 is the row itself
    if model.first_order == "forward":  # the forward model's G_r in the fitted metric
        Gr, _ = model._forward_first_order(changed, model.feature_precision_)
    else:
        Gr = pinv_blocks(H[:, :m, :])
        if model.project_features:  # G_r = G_u^- pi_W: pi_W from the feature-space neighbours
            d2, ind = model._query_w(model._ws[changed], model.n_neighbors + 1)
            w = np.exp(-0.5 * d2[:, 1:] / model._pca_bw ** 2)
            Uw = local_pca(model._ws, model._ws[changed], ind[:, 1:], w, Gr.shape[1])
            Gr = (Gr @ Uw) @ np.swapaxes(Uw, 1, 2)
    model.Gr_[changed] = Gr
    _, ind_t = model._zv_tree.query(model._zv, k=model.jr_neighbors_ + 1)  # O(n log n), 4-D
    model.theta_radius_ = np.linalg.norm(
        model._pose_diff(model.theta_, model.theta_[ind_t[:, -1:]])[:, 0], axis=1)
    model.partial_fit_rows_ = changed
    return model
