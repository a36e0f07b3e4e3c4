"""The queries of a fitted :class:`~localization.gse.regressor.GSERegressor` (a mixin):
r*(w) and R*(theta) by Jacobian Regression with their exact Jacobians, and their composition
with the recovery map, psi*(w) = g_v(r*(w)) and Phi*(theta) = g_u(R*(theta))
(docs/method.md §8). Uses the fitted attributes the regressor sets in ``fit`` / ``_setup``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from sklearn.utils.validation import check_is_fitted

from localization._validation import check_int
from localization.geometry import wrap_angle
from localization.gse.graph import Array, brute_knn, local_pca, same_side
from localization.gse.jacobian_regression import gaussian_jr
from localization.gse.validation import check_2d, validate_X

__all__ = ["KDTREE_MAX_DIM", "GSEQueryMixin"]

#: features up to this width answer a few rows from a KD-tree, wider ones from a GEMM over all
#: samples: one query, 10 neighbours, of 6000-45000 PixelPCA rows (a 15000-image route map's
#: leading columns), KD-tree / GEMM 0.03-0.18 / 0.10-0.78 ms at 16 features, 0.12-0.59 /
#: 0.12-0.76 at 32, 0.21-1.94 / 0.16-1.26 at 64 and 0.36-5.5 / 0.15-2.8 at 128 (stop 58,
#: docs/method.md §17)
KDTREE_MAX_DIM = 32


class GSEQueryMixin:
    """psi*, Phi*, r*, R* and their Jacobians on a fitted GSE regressor."""

    gse_: Any
    w_mean_: Array
    w_scale_: Array
    theta_scale_: Array
    embedding_: Array
    out_of_domain: str
    _memo: dict[str, tuple[tuple[bytes, str], Array, Array | None]]
    _ws_tree: Any  # a cKDTree of the standardised features, None beyond KDTREE_MAX_DIM

    def _check_w(self, W: Array) -> Array:
        check_is_fitted(self, "gse_")
        return validate_X(self, W, "W", reset=False)

    def _check_theta(self, Theta: Array) -> Array:
        check_is_fitted(self, "gse_")
        return check_2d(Theta, "Theta", len(self.theta_scale_))

    def _flag(self, log_sum: Array, what: str, *outs: Array) -> None:
        bad = log_sum < np.log(self.gse_.min_kernel_sum)
        if bad.any() and self.out_of_domain != "ignore":
            if self.out_of_domain == "raise":
                raise ValueError(f"{bad.sum()} {what} row(s) are outside the training domain "
                                 f"(kernel sum < {self.gse_.min_kernel_sum:g}), first row "
                                 f"{int(np.flatnonzero(bad)[0])}")
            for o in outs:
                if o is not None:
                    o[bad] = np.nan

    def _mask(self, ind: Array) -> Array | None:
        """Neighbours (n, k) on the nearest neighbour's side of every cut, or None."""
        return None if self.cut_ is None else same_side(self.cut_[ind])

    def _w_factor(self, Ws: Array, ind: Array) -> Array | None:
        """log Binet-Cauchy factor of K_W (n, k), or None when kernel_grassmann is off."""
        if not self.kernel_grassmann:
            return None
        d2 = ((Ws[:, None, :] - self._ws[ind]) ** 2).sum(axis=2)
        L = local_pca(self._ws, Ws, ind, np.exp(-0.5 * d2 / self._pca_bw ** 2),
                      self.embedding_.shape[1])
        S = np.einsum("nma,nkmb->nkab", L, self._w_tangents[ind])
        with np.errstate(divide="ignore"):
            return np.log(np.linalg.det(S) ** 2)

    def _query_w(self, Ws: Array, k: int) -> tuple[Array, Array]:
        """k nearest training features (squared distances, indices) of standardised rows:
        the HNSW index on the approximate path, else a KD-tree for a few rows of at most
        :data:`KDTREE_MAX_DIM` features (it beats a GEMM over all samples there) and a
        brute-force GEMM otherwise."""
        if getattr(self, "_ws_index", None) is not None:
            return self._ws_index.query(Ws, k)
        if len(Ws) <= 32 and self._ws_tree is not None:
            d, ind = self._ws_tree.query(Ws, k=k)
            return (np.asarray(d).reshape(len(Ws), -1) ** 2,
                    np.asarray(ind).reshape(len(Ws), -1))
        return brute_knn(self._ws, self._ws_sqn, Ws, k)

    def _one_row(self, kind: str, X: Array, jacobian: bool,
                 compute: Callable[[Array, bool], tuple[Array, Array | None]]
                 ) -> tuple[Array, Array | None]:
        """``compute(X, True)`` for a validated single row ``X``, remembered for the next
        call with the same row: a filter step asks for r*(w) (its measurement) and psi*(w)
        (its monitor) of one image, and for R*(x) and its Jacobian (h and H) at one pose.
        The last row of each ``kind`` is kept (``_setup`` forgets them) with the
        ``out_of_domain`` setting it was answered under (the one option read at query time);
        copies go out."""
        key = (X.tobytes(), self.out_of_domain)
        memo = self._memo.get(kind)
        if memo is None or memo[0] != key:
            memo = (key, *compute(X, True))
            self._memo[kind] = memo
        return memo[1].copy(), memo[2].copy() if jacobian else None

    def _r_star(self, W: Array, jacobian: bool) -> tuple[Array, Array | None]:
        W = self._check_w(W)
        if len(W) == 1:
            return self._one_row("w", W, jacobian, self._r_star_rows)
        return self._r_star_rows(W, jacobian)

    def _r_star_rows(self, W: Array, jacobian: bool) -> tuple[Array, Array | None]:
        Ws = (W - self.w_mean_) / self.w_scale_
        ind = self._query_w(Ws, self.jr_neighbors_)[1]
        mask = self._mask(ind)
        bw = self.bandwidth_w_ * self.w_radius_[ind] if self.adaptive_bandwidth else self.bandwidth_w_
        r, J, log_sum = gaussian_jr(Ws[:, None, :] - self._ws[ind], self.embedding_[ind],
                                    self.Gr_[ind], bw, mask, jacobian,
                                    self._w_factor(Ws, ind), self.agreement_)
        if J is not None:
            J /= self.w_scale_
        self._flag(log_sum, "W", r, J)
        return r, J

    def _R_star(self, Theta: Array, jacobian: bool) -> tuple[Array, Array | None]:
        Theta = self._check_theta(Theta)
        if len(Theta) == 1:
            return self._one_row("theta", Theta, jacobian, self._R_star_rows)
        return self._R_star_rows(Theta, jacobian)

    def _R_star_rows(self, Theta: Array, jacobian: bool) -> tuple[Array, Array | None]:
        Theta = Theta.copy()
        for c in self._per:
            Theta[:, c] = wrap_angle(Theta[:, c])
        _, ind = self._zv_tree.query(self._lift(Theta), k=self.jr_neighbors_)
        ind = np.asarray(ind).reshape(len(Theta), -1)
        mask = self._mask(ind)
        bw = (self.bandwidth_theta_ * self.theta_radius_[ind] if self.adaptive_bandwidth
              else self.bandwidth_theta_)
        R, J, log_sum = gaussian_jr(self._pose_diff(Theta, self.theta_[ind]), self.embedding_[ind],
                                    self.GR_[ind], bw, mask, jacobian)
        if J is not None:
            J *= self.theta_scale_
        self._flag(log_sum, "Theta", R, J)
        return R, J

    def embed(self, W: Array) -> Array:
        """r*(w): representation of features, shape (n, q)."""
        return self._r_star(W, False)[0]

    def embed_jacobian(self, W: Array) -> Array:
        """Exact d r*/dw in original feature units, shape (n, q, m)."""
        return self._r_star(W, True)[1]

    def embed_pose(self, Theta: Array) -> Array:
        """R*(theta): representation of poses, shape (n, q)."""
        return self._R_star(Theta, False)[0]

    def embed_pose_jacobian(self, Theta: Array) -> Array:
        """Exact d R*/dtheta (angles in radians), shape (n, q, d)."""
        return self._R_star(Theta, True)[1]

    def embed_pose_with_jacobian(self, Theta: Array) -> tuple[Array, Array]:
        """R*(theta) (n, q) and d R*/dtheta (n, q, d) from one neighbour query (a particle
        filter's likelihood and its linearisation at every particle)."""
        R, J = self._R_star(Theta, True)
        return R, J

    def _recover(self, Y: Array, cols: slice, jacobian: bool = False
                 ) -> tuple[Array, Array | None]:
        """g(Y) on ambient columns ``cols``; rows of Y that are NaN (out of domain with
        ``out_of_domain="nan"``) stay NaN instead of reaching the KD-tree."""
        ok = np.all(np.isfinite(Y), axis=1)
        if ok.all():
            g, J, _ = self.gse_._recover(Y, cols, jacobian)
            return g, J
        p = len(range(*cols.indices(self.gse_.Z_.shape[1])))
        g = np.full((len(Y), p), np.nan)
        J = np.full((len(Y), p, Y.shape[1]), np.nan) if jacobian else None
        if ok.any():
            g[ok], Jok, _ = self.gse_._recover(Y[ok], cols, jacobian)
            if J is not None:
                J[ok] = Jok
        return g, J

    def predict(self, W: Array) -> Array:
        """psi*(w) = g_v(r*(w)): poses (n, d) (or (n,) if fitted on a 1-D y), angles
        wrapped to (-pi, pi]."""
        r, _ = self._r_star(W, False)
        zv, _ = self._recover(r, slice(len(self.w_mean_), None))
        theta = self._unlift(zv)
        return theta[:, 0] if getattr(self, "y_1d_", False) else theta

    def kneighbors(self, W: Array, n_neighbors: int) -> tuple[Array, Array]:
        """The ``n_neighbors`` training samples nearest to each row of ``W`` (n, m) in the
        standardised feature space, by the index the queries use (HNSW with exact
        re-ranking on the approximate path; a KD-tree or a GEMM on the exact one).

        Returns
        -------
        distances : ndarray (n, k)
            Ascending, in standardised feature units.
        indices : ndarray (n, k)
            Rows of the training sample (``theta_``), ``k = min(n_neighbors, n_train)``.
        """
        W = self._check_w(W)
        k = check_int(n_neighbors, "n_neighbors", low=1)
        d2, ind = self._query_w((W - self.w_mean_) / self.w_scale_, min(k, len(self.gse_.Z_)))
        return np.sqrt(np.maximum(d2, 0.0)), np.asarray(ind, dtype=np.intp)

    def predict_features(self, Theta: Array) -> Array:
        """Phi*(theta) = g_u(R*(theta)): features (n, m) in original units."""
        R, _ = self._R_star(Theta, False)
        gu, _ = self._recover(R, slice(0, len(self.w_mean_)))
        return gu * self.w_scale_ + self.w_mean_

    def reconstruct(self, W: Array) -> Array:
        """Reduce-then-recover ``g_u(r*(w))``: features (n, m) rebuilt from their
        q-dimensional representation (the paper's Fig. 2), original units."""
        r, _ = self._r_star(W, False)
        gu, _, _ = self.gse_._recover(r, slice(0, len(self.w_mean_)))
        return gu * self.w_scale_ + self.w_mean_

    def novelty(self, W: Array) -> Array:
        """Distance (n,) of features W (n, m) from the learned feature manifold,
        ``|w - g_u(r*(w))|`` (reduce-then-recover; NaN out of the domain): large for an image
        unlike every training image (another light, an occluder)."""
        return np.linalg.norm(W - self.reconstruct(W), axis=1)

    def training_novelty(self, sample: int = 500) -> Array:
        """:meth:`novelty` (k,) of at most ``sample`` evenly spaced training samples (their
        features recovered from the standardised ones the model keeps): the scale of a
        familiar image."""
        rows = np.unique(np.linspace(0, len(self._ws) - 1, min(sample, len(self._ws))).astype(int))
        return self.novelty(self._ws[rows] * self.w_scale_ + self.w_mean_)

    def feature_tangents(self, W: Array) -> Array:
        """Tangent vectors of the feature manifold at ``g_u(r*(w))``: the feature block
        ``G_u`` of the recovery Jacobian field (method §7.2), shape (n, m, q), original units
        per unit of representation (the paper's Fig. 3)."""
        r, _ = self._r_star(W, False)
        out = np.full((len(r), len(self.w_mean_), r.shape[1]), np.nan)
        ok = np.isfinite(r).all(axis=1)
        if ok.any():
            out[ok] = self.gse_.recovery_jacobian(r[ok])[:, :len(self.w_mean_), :]
        return out * self.w_scale_

    def features_jacobian(self, Theta: Array) -> Array:
        """Exact dPhi*/dtheta (n, m, d) in original units (angles in radians): EKF's H."""
        R, JR = self._R_star(Theta, True)
        _, Jg = self._recover(R, slice(0, len(self.w_mean_)), jacobian=True)
        return self.w_scale_ * (Jg @ JR)

    def features_and_jacobian(self, Theta: Array) -> tuple[Array, Array]:
        """Phi*(theta) (n, m) and dPhi*/dtheta (n, m, d) from one evaluation of R*
        (:meth:`predict_features` and :meth:`features_jacobian` together)."""
        R, JR = self._R_star(Theta, True)
        gu, Jg = self._recover(R, slice(0, len(self.w_mean_)), jacobian=True)
        assert Jg is not None and JR is not None
        return gu * self.w_scale_ + self.w_mean_, self.w_scale_ * (Jg @ JR)
