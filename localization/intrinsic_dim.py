"""Intrinsic dimension estimates as in the seed paper's Table I (section V).

Three estimators, one per column of Table I:

* global (:func:`global_dimension`): Isomap residual variance (Tenenbaum et al. 2000),
  with ``sklearn.manifold.Isomap``;
* local (:func:`local_dimension`): correlation dimension (Grassberger-Procaccia),
  ``skdim.id.CorrInt``;
* pointwise (:func:`pointwise_dimension`): Levina-Bickel maximum likelihood per point,
  ``skdim.id.MLE``, aggregated over points.

scikit-dimension 0.5.0 works with the pinned numpy 2.4 / scipy 1.17 (checked: CorrInt and
MLE recover 1, 2, 3 on a helix, swiss roll and curved 3-manifold). If an estimator fails to
import or raises, a short numpy fallback of the same formula is used and
``details["fallback"]`` says why.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse.csgraph import connected_components, shortest_path
from scipy.spatial.distance import pdist
from sklearn.manifold import Isomap
from sklearn.neighbors import NearestNeighbors, kneighbors_graph

from localization.geometry import Array

__all__ = ["DimensionEstimate", "global_dimension", "intrinsic_dimension_table",
           "local_dimension", "loop_cut_mask", "pointwise_dimension"]


@dataclass
class DimensionEstimate:
    """One intrinsic-dimension estimate.

    Attributes
    ----------
    value : float
        The estimate (an integer for the Isomap rule, a real number otherwise).
    rounded : int
        ``max(1, round(value))``.
    method : str
    details : dict
        Method-specific diagnostics (curves, per-point values, parameters, fallbacks).
    """

    value: float
    method: str
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def rounded(self) -> int:
        return max(1, round(self.value))

    def __float__(self) -> float:
        return float(self.value)


def _prepare(X: ArrayLike, min_samples: int, max_samples: int | None, seed: int,
             ) -> tuple[Array, dict[str, Any]]:
    """Validate, drop exact duplicates (zero distances break the estimators), subsample."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2:
        raise ValueError(f"X must be 2-D (n_samples, n_features), got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("X contains NaN or inf")
    info: dict[str, Any] = {"n_input": int(X.shape[0])}
    Xu = np.unique(X, axis=0)
    if len(Xu) < len(X):
        info["duplicates_dropped"] = int(len(X) - len(Xu))
        X = Xu
    if max_samples is not None and len(X) > max_samples:
        rng = np.random.default_rng(seed)
        X = X[np.sort(rng.choice(len(X), max_samples, replace=False))]
        info["subsampled_to"] = int(max_samples)
    if len(X) < min_samples:
        raise ValueError(f"need at least {min_samples} distinct samples, got {len(X)}")
    return X, info


def loop_cut_mask(X: Array, n_neighbors: int = 12, cut_fraction: float = 0.1,
                  seed: int = 0) -> tuple[Array, bool]:
    """Points to keep so that a closed loop becomes an open arc (Isomap cannot embed a loop
    in R^1: a circle's geodesic distances need two dimensions).

    On the k-NN graph (edge lengths = distances), from a random point a take the farthest
    point b (the antipode on a loop) and the geodesic distances g from b. The data form a
    loop if the points at mid-range, ``0.45 <= g / max(g) <= 0.55``, fall in two or more
    connected pieces of the graph (the two branches of the loop between b and a); then the
    points within ``cut_fraction * max(g)`` of b are dropped (the cut). Otherwise nothing is
    dropped.

    Parameters
    ----------
    X : ndarray of shape (n, p)
    n_neighbors : int, default=12
    cut_fraction : float, default=0.1
        Geodesic radius of the cut relative to the largest distance from b.
    seed : int, default=0
        Seed of the start point a.

    Returns
    -------
    keep : ndarray of bool, shape (n,)
    is_loop : bool
    """
    if not 0.0 < cut_fraction < 0.5:
        raise ValueError(f"cut_fraction must be in (0, 0.5), got {cut_fraction}")
    G = kneighbors_graph(X, n_neighbors, mode="distance")
    G = G.maximum(G.T).tocsr()
    a = int(np.random.default_rng(seed).integers(len(X)))
    ga = shortest_path(G, directed=False, indices=[a])[0]
    b = int(np.argmax(np.where(np.isfinite(ga), ga, -1.0)))
    g = shortest_path(G, directed=False, indices=[b])[0]
    g = np.where(np.isfinite(g), g, np.inf)
    gmax = float(g[np.isfinite(g)].max())
    mid = np.flatnonzero((g >= 0.45 * gmax) & (g <= 0.55 * gmax))
    n_pieces = int(connected_components(G[mid][:, mid], directed=False)[0]) if len(mid) else 0
    if n_pieces < 2:
        return np.ones(len(X), dtype=bool), False
    return g > cut_fraction * gmax, True


def global_dimension(X: ArrayLike, d_max: int = 6, n_neighbors: int = 12, rel_tol: float = 0.25,
                     abs_tol: float = 1e-3, max_samples: int | None = 2000,
                     seed: int = 0, cut_loop: bool = False) -> DimensionEstimate:
    """Global intrinsic dimension from the Isomap residual-variance curve.

    For d = 1..d_max, ``rv(d) = 1 - R^2`` between the Isomap geodesic distances and
    the Euclidean distances of the d-dimensional Isomap embedding (one Isomap fit with
    ``d_max`` components; the embeddings are nested). Rule (the "elbow"): the smallest
    d at which the curve stops falling, i.e.
    ``rv(d) - rv(d+1) < max(rel_tol * rv(d), abs_tol)``; ``d_max`` (with a warning)
    if it never stops. A pure threshold on rv fails on long thin manifolds (a swiss
    roll has rv(1) ~ 0.014), hence the relative rule.

    Parameters
    ----------
    X : array_like of shape (n, p)
    d_max : int, default=6
    n_neighbors : int, default=12
        Isomap neighbourhood graph size. A disconnected graph is reported in
        ``details["n_graph_components"]`` (Isomap then links components, unreliable).
    rel_tol, abs_tol : float
        Elbow rule tolerances (see above).
    max_samples : int or None, default=2000
        Random subsample size (Isomap needs O(n^2) memory and time).
    seed : int, default=0
        Subsampling seed (and the start point of the loop test).
    cut_loop : bool, default=False
        Test for a closed loop and cut it once before Isomap (:func:`loop_cut_mask`): a
        closed curve then reads 1, not 2. ``details["loop_cut"]`` says whether it was cut.

    Returns
    -------
    DimensionEstimate
        ``details["residual_variance"]`` has shape (d_max,), index d-1.
    """
    if d_max < 1:
        raise ValueError(f"d_max must be >= 1, got {d_max}")
    X, info = _prepare(X, max(n_neighbors + 2, d_max + 2), max_samples, seed)
    if cut_loop:
        keep, info["loop_cut"] = loop_cut_mask(X, n_neighbors, seed=seed)
        X = X[keep]
    d_max = min(d_max, X.shape[1])
    graph = kneighbors_graph(X, n_neighbors, mode="connectivity")
    n_comp = int(connected_components(graph, directed=False)[0])
    info.update(n_neighbors=n_neighbors, n_graph_components=n_comp)
    if n_comp > 1:
        warnings.warn(f"Isomap neighbourhood graph has {n_comp} components; increase "
                      "n_neighbors", stacklevel=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # sklearn's own disconnected-graph warnings
        iso = Isomap(n_neighbors=n_neighbors, n_components=d_max).fit(X)
    geo = iso.dist_matrix_[np.triu_indices(len(X), 1)]
    rv = np.empty(d_max)
    for d in range(1, d_max + 1):
        r = np.corrcoef(geo, pdist(iso.embedding_[:, :d]))[0, 1]
        rv[d - 1] = 1.0 - r * r
    dim = d_max
    for d in range(1, d_max):
        if rv[d - 1] - rv[d] < max(rel_tol * rv[d - 1], abs_tol):
            dim = d
            break
    else:
        if d_max > 1:
            warnings.warn(f"Isomap residual variance still falling at d_max={d_max}",
                          stacklevel=2)
    info.update(residual_variance=rv, rule=f"first d with rv(d)-rv(d+1) < max({rel_tol}*rv(d), "
                f"{abs_tol})")
    return DimensionEstimate(float(dim), "isomap_residual_variance", info)


def _corr_dim_numpy(X: Array, k1: int, k2: int) -> float:
    """Grassberger-Procaccia slope between the median k1-th and k2-th NN distances."""
    dist, _ = NearestNeighbors(n_neighbors=k2).fit(X).kneighbors()
    r1, r2 = np.median(dist[:, k1 - 1]), np.median(dist[:, k2 - 1])
    d = pdist(X)
    c1, c2 = np.mean(d < r1), np.mean(d < r2)
    return float(np.log(c2 / c1) / np.log(r2 / r1))


def local_dimension(X: ArrayLike, k1: int = 10, k2: int = 20, max_samples: int | None = 5000,
                    seed: int = 0) -> DimensionEstimate:
    """Correlation dimension (``skdim.id.CorrInt``).

    Slope of log C(r) (fraction of point pairs closer than r) between r1 and r2, the
    median distances to the k1-th and k2-th nearest neighbours.

    Parameters
    ----------
    X : array_like of shape (n, p)
    k1, k2 : int, default=10, 20
        Neighbour ranks defining the scale range.
    max_samples : int or None, default=5000
        Random subsample size (the pair count is O(n^2)).
    seed : int, default=0

    Returns
    -------
    DimensionEstimate
    """
    if not 1 <= k1 < k2:
        raise ValueError(f"need 1 <= k1 < k2, got k1={k1}, k2={k2}")
    X, info = _prepare(X, k2 + 2, max_samples, seed)
    info.update(k1=k1, k2=k2)
    try:
        import skdim

        value = float(skdim.id.CorrInt(k1=k1, k2=k2).fit(X).dimension_)
        method = "skdim.id.CorrInt"
    except Exception as exc:  # noqa: BLE001  # pragma: no cover - any skdim failure
        info["fallback"] = f"skdim.id.CorrInt failed ({exc!r}); numpy Grassberger-Procaccia used"
        value, method = _corr_dim_numpy(X, k1, k2), "correlation_dimension_numpy"
    return DimensionEstimate(value, method, info)


def _mle_numpy(X: Array, k: int) -> Array:
    """Levina-Bickel pointwise MLE: 1 / mean_{j<k} log(T_k / T_j)."""
    dist, _ = NearestNeighbors(n_neighbors=k).fit(X).kneighbors()
    return 1.0 / np.mean(np.log(dist[:, -1:] / dist[:, :-1]), axis=1)


def pointwise_dimension(X: ArrayLike, n_neighbors: int = 20, aggregate: str = "mean",
                        max_samples: int | None = None, seed: int = 0) -> DimensionEstimate:
    """Levina-Bickel maximum-likelihood dimension per point (``skdim.id.MLE``), aggregated.

    Parameters
    ----------
    X : array_like of shape (n, p)
    n_neighbors : int, default=20
        k of the per-point likelihood.
    aggregate : {"mean", "median", "mle"}, default="mean"
        How the per-point values become one number; ``"mle"`` is the harmonic mean
        (MacKay-Ghahramani). All three are in ``details``.
    max_samples : int or None, default=None
    seed : int, default=0

    Returns
    -------
    DimensionEstimate
        ``details["pointwise"]`` has shape (n,), plus ``mean``, ``median``, ``mle``.
    """
    if aggregate not in ("mean", "median", "mle"):
        raise ValueError(f"aggregate must be 'mean', 'median' or 'mle', got {aggregate!r}")
    if n_neighbors < 2:
        raise ValueError(f"n_neighbors must be >= 2, got {n_neighbors}")
    X, info = _prepare(X, n_neighbors + 2, max_samples, seed)
    try:
        import skdim

        pw = np.asarray(skdim.id.MLE().fit(X, n_neighbors=n_neighbors).dimension_pw_, float)
        method = "skdim.id.MLE"
    except Exception as exc:  # noqa: BLE001  # pragma: no cover - any skdim failure
        info["fallback"] = f"skdim.id.MLE failed ({exc!r}); numpy Levina-Bickel used"
        pw, method = _mle_numpy(X, n_neighbors), "levina_bickel_numpy"
    pw = pw[np.isfinite(pw)]
    if pw.size == 0:
        raise ValueError("all pointwise MLE estimates are non-finite")
    stats = {"mean": float(np.mean(pw)), "median": float(np.median(pw)),
             "mle": float(1.0 / np.mean(1.0 / pw))}
    info.update(n_neighbors=n_neighbors, aggregate=aggregate, pointwise=pw, **stats)
    return DimensionEstimate(stats[aggregate], method, info)


def intrinsic_dimension_table(X: ArrayLike, seed: int = 0) -> dict[str, Any]:
    """The three Table I estimates for one data set, with default settings.

    Parameters
    ----------
    X : array_like of shape (n, p)
    seed : int, default=0
        Subsampling seed.

    Returns
    -------
    dict
        ``{"global": float, "local": float, "pointwise": float,
        "rounded": {"global": int, "local": int, "pointwise": int},
        "estimates": {name: DimensionEstimate}}``.
    """
    est = {"global": global_dimension(X, seed=seed), "local": local_dimension(X, seed=seed),
           "pointwise": pointwise_dimension(X, seed=seed)}
    table: dict[str, Any] = {k: float(v.value) for k, v in est.items()}
    table["rounded"] = {k: v.rounded for k, v in est.items()}
    table["estimates"] = est
    return table
