"""Nearest-neighbour search of GSE: exact, or approximate with faiss HNSW.

``algorithm`` of :class:`~localization.gse.embedding.GrassmannStiefelEigenmaps` and
:class:`~localization.gse.regressor.GSERegressor`:

* ``"exact"``: scikit-learn's ``NearestNeighbors`` for the kNN graph, a BLAS brute force
  (or a KD-tree for a few rows) for queries: O(n^2 p) for the graph.
* ``"approximate"``: a faiss HNSW graph index (``IndexHNSWFlat``), O(n log n) to build and
  O(log n) a query. The index proposes ``k + oversample`` candidates in float32; their
  distances are recomputed exactly in float64 and re-ranked, so every returned distance is
  exact and only a missed true neighbour is approximate (recall in the benchmark).
* ``"auto"``: ``"approximate"`` from :data:`APPROXIMATE_MIN_N` samples on.

faiss (not pynndescent): no JIT compilation (pynndescent's numba kernels cost ~50 s in a
fresh process, more than the whole fit at n = 100k), single queries in ~0.1 ms, and a
deterministic build when it runs on one thread, which :class:`HNSWIndex` enforces (the
same data give the same graph; searches are per query, so any thread count gives the same
answer).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from localization.geometry import Array

__all__ = ["ALGORITHMS", "APPROXIMATE_MIN_N", "HNSWIndex", "approximate_knn_graph",
           "knn_graph_any", "use_approximate"]

#: ``algorithm="auto"`` switches to the approximate path from this many samples on.
APPROXIMATE_MIN_N = 20000
ALGORITHMS = ("auto", "exact", "approximate")
_CHUNK = 8192


def use_approximate(algorithm: str, n: int) -> bool:
    """Whether ``algorithm`` ("auto", "exact", "approximate") runs the approximate path
    on ``n`` samples."""
    if algorithm not in ALGORITHMS:
        raise ValueError(f"unknown algorithm {algorithm!r}; choose one of {ALGORITHMS}")
    return algorithm == "approximate" or (algorithm == "auto" and n >= APPROXIMATE_MIN_N)


def _faiss() -> Any:
    try:
        import faiss
    except ImportError as exc:  # a core dependency; only a broken install gets here
        raise ImportError("algorithm='approximate' needs faiss-cpu (pip install faiss-cpu)"
                          ) from exc
    return faiss


class HNSWIndex:
    """Approximate k-nearest-neighbour index (faiss ``IndexHNSWFlat``) with exact re-ranking.

    Parameters
    ----------
    X : ndarray of shape (n, p)
        The indexed rows (kept by reference: rows appended with :meth:`add` must be
        appended to the caller's array too, see :meth:`add`).
    n_links : int, default=32
        HNSW ``M`` (links per node).
    ef_construction : int, default=64
    ef_search : int, default=64
        Candidate list length of a search (at least ``k + oversample``).
    oversample : int, default=8
        Extra candidates re-ranked with exact distances.
    """

    def __init__(self, X: Array, n_links: int = 32, ef_construction: int = 64,
                 ef_search: int = 64, oversample: int = 8) -> None:
        faiss = _faiss()
        self.X = np.ascontiguousarray(X, dtype=np.float64)
        self.ef_search, self.oversample = ef_search, oversample
        self.index = faiss.IndexHNSWFlat(self.X.shape[1], n_links)
        self.index.hnsw.efConstruction = ef_construction
        self._add(self.X)
        self._set_guard()

    def _set_guard(self) -> None:
        """Squared distance beyond which a search result is re-checked by brute force:
        (2 x the 99th percentile of the nearest-neighbour distances of up to 512 indexed
        rows)^2. A graph search can stop in a wrong region (seen at n = 40k: one of 1000
        held-out queries got neighbours 9x farther than its true ones, and position RRMSE
        went from 0.0018 to 0.027); such a result is far, and the brute force (a GEMM,
        O(n p)) then gives the exact answer. Queries genuinely far from the sample take
        the same exact path."""
        n = len(self.X)
        self._sqn = (self.X ** 2).sum(axis=1)
        if n < 3:
            self.guard_d2 = np.inf
            return
        rows = np.unique(np.linspace(0, n - 1, min(n, 512)).astype(np.intp))
        cand = self.candidates(self.X[rows], 2)
        other = np.where(cand[:, 0] == rows, cand[:, 1], cand[:, 0])
        d = np.sqrt(((self.X[other] - self.X[rows]) ** 2).sum(axis=1))
        self.guard_d2 = float((2.0 * np.percentile(d, 99)) ** 2)

    def _add(self, X: Array) -> None:
        faiss = _faiss()
        threads = faiss.omp_get_max_threads()
        faiss.omp_set_num_threads(1)  # a parallel build depends on thread timing
        try:
            self.index.add(np.ascontiguousarray(X, dtype=np.float32))
        finally:
            faiss.omp_set_num_threads(threads)

    def add(self, X_all: Array) -> None:
        """Index the rows of ``X_all`` (n_new_total, p) beyond those already indexed;
        ``X_all`` is the caller's (grown) sample and replaces the kept reference."""
        n0 = self.index.ntotal
        self.X = np.ascontiguousarray(X_all, dtype=np.float64)
        self._add(self.X[n0:])
        self._sqn = (self.X ** 2).sum(axis=1)

    def candidates(self, Xq: Array, k: int) -> NDArray[np.intp]:
        """Approximate ``k`` nearest rows (n_q, k) of each query (float32 ranking)."""
        k = min(k, self.index.ntotal)
        self.index.hnsw.efSearch = max(self.ef_search, k)
        _, ind = self.index.search(np.ascontiguousarray(Xq, dtype=np.float32), k)
        return ind.astype(np.intp)

    def query(self, Xq: Array, k: int) -> tuple[Array, NDArray[np.intp]]:
        """``k`` nearest rows of each query, re-ranked by exact float64 distance.

        Returns
        -------
        d2 : ndarray of shape (n_q, k)
            Exact squared distances, ascending.
        ind : ndarray of shape (n_q, k)
        """
        k = min(k, self.index.ntotal)
        d2 = np.empty((len(Xq), k))
        ind = np.empty((len(Xq), k), dtype=np.intp)
        for s in range(0, len(Xq), _CHUNK):
            xq = Xq[s:s + _CHUNK]
            cand = self.candidates(xq, k + self.oversample)
            exact = ((self.X[cand] - xq[:, None, :]) ** 2).sum(axis=2)
            exact[cand < 0] = np.inf  # a short candidate list pads with -1
            order = np.argsort(exact, axis=1, kind="stable")[:, :k]
            first = np.take_along_axis(exact, order, axis=1)
            # too few candidates (padded with -1), or a search that stopped far away
            redo = np.flatnonzero(~np.isfinite(first).all(axis=1) | (first[:, 0] > self.guard_d2))
            if redo.size:
                from localization.gse.graph import brute_knn

                exact_r, cand_r = brute_knn(self.X, self._sqn, xq[redo], cand.shape[1])
                cand, exact, order = cand.copy(), exact.copy(), order.copy()
                cand[redo, :cand_r.shape[1]], exact[redo, :cand_r.shape[1]] = cand_r, exact_r
                order[redo] = np.arange(k)
            ind[s:s + _CHUNK] = np.take_along_axis(cand, order, axis=1)
            d2[s:s + _CHUNK] = np.take_along_axis(exact, order, axis=1)
        return d2, ind


def approximate_knn_graph(X: Array, n_neighbors: int, index: HNSWIndex | None = None
                          ) -> tuple[Array, NDArray[np.intp], HNSWIndex]:
    """kNN graph of the rows of ``X`` (excluding each row itself) from an HNSW index.

    Returns distances (n, k) (exact, ascending), indices (n, k) and the index.
    """
    index = HNSWIndex(X) if index is None else index
    n = len(X)
    d2, ind = index.query(X, n_neighbors + 1)
    keep = ind != np.arange(n)[:, None]
    over = keep.sum(axis=1) > n_neighbors  # self found: drop it; else drop the farthest
    keep[over, -1] = False
    return (np.sqrt(d2[keep].reshape(n, n_neighbors)), ind[keep].reshape(n, n_neighbors),
            index)


def knn_graph_any(X: Array, n_neighbors: int, approximate: bool
                  ) -> tuple[Array, NDArray[np.intp], HNSWIndex | None]:
    """kNN graph (distances, indices; self excluded) exactly (scikit-learn, with the
    duplicate check of :func:`~localization.gse.graph.knn_graph`) or from an HNSW index
    (returned for later queries; None on the exact path)."""
    from localization.gse.graph import knn_graph

    if not approximate:
        return (*knn_graph(X, n_neighbors), None)
    if n_neighbors < 1 or n_neighbors >= len(X):
        return (*knn_graph(X, n_neighbors), None)  # raises its clear error
    dist, ind, index = approximate_knn_graph(X, n_neighbors)
    scale = max(float(np.median(dist[:, -1])), np.finfo(float).tiny)
    dup = dist[:, 0] <= 1e-12 * scale
    if dup.any():
        i = np.flatnonzero(dup)
        pairs = [(int(a), int(ind[a, 0])) for a in i[:5]]
        raise ValueError(f"{dup.sum()} sample(s) duplicate another sample, e.g. index pairs "
                         f"{pairs}: remove duplicate points before fitting")
    return dist, ind, index
