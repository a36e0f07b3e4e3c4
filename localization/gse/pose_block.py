"""Pose block of GSERegressor's ambient vectors ``Z = (standardised w, lifted theta)``.

Linear pose columns enter Z as ``theta_scale x (theta - centre)``; a periodic column
(yaw) as a (cos, sin) pair of radius ``theta_scale``. :class:`PoseBlockMixin` holds the
lift, its inverse and derivative, wrapped pose differences, and the automatic scale
(feature sensitivity per unit group). Expects ``theta_scale_``, ``theta_center_`` and
``_per`` (the periodic columns) on the instance.
"""

from __future__ import annotations

import warnings

import numpy as np

from localization.geometry import Array, wrap_angle


class PoseBlockMixin:
    """Lift of poses into the pose block of Z (see the module docstring)."""

    periodic: tuple[int, ...]
    theta_scale_: Array
    theta_center_: Array
    _per: tuple[int, ...]

    def _periodic(self, d: int) -> tuple[int, ...]:
        per = tuple(sorted({int(c) for c in self.periodic}))
        if any(c < 0 or c >= d for c in per):
            raise ValueError(f"periodic={self.periodic} has columns outside Theta's {d} columns")
        if len(per) > 1:
            raise ValueError(f"at most one periodic column is supported, got {per}")
        return per

    def _lift(self, theta: Array) -> Array:
        """Pose block of Z: scaled linear columns, (cos, sin) x scale for the angle."""
        cols = []
        for c in range(theta.shape[1]):
            lam = self.theta_scale_[c]
            if c in self._per:
                cols += [lam * np.cos(theta[:, c]), lam * np.sin(theta[:, c])]
            else:
                cols.append(lam * (theta[:, c] - self.theta_center_[c]))
        return np.column_stack(cols)

    def _unlift(self, zv: Array) -> Array:
        out, j = [], 0
        for c in range(len(self.theta_scale_)):
            if c in self._per:
                out.append(np.arctan2(zv[:, j + 1], zv[:, j]))
                j += 2
            else:
                out.append(zv[:, j] / self.theta_scale_[c] + self.theta_center_[c])
                j += 1
        return np.column_stack(out)

    def _pose_diff(self, theta: Array, theta_nb: Array) -> Array:
        """Scaled pose differences (n, k, d), angle differences wrapped."""
        dt = theta[:, None, :] - theta_nb
        for c in self._per:
            dt[..., c] = wrap_angle(dt[..., c])
        return dt * self.theta_scale_

    def _dlift(self, theta: Array) -> Array:
        """d(pose block)/d(scaled theta), shape (n, p_v, d)."""
        n, d = theta.shape
        E = np.zeros((n, d + len(self._per), d))
        j = 0
        for c in range(d):
            if c in self._per:
                E[:, j, c], E[:, j + 1, c] = -np.sin(theta[:, c]), np.cos(theta[:, c])
                j += 2
            else:
                E[:, j, c] = 1.0
                j += 1
        return E

    def _auto_scale(self, Ws: Array, Theta: Array, ind_w: Array) -> Array:
        """Feature sensitivity |dw/dtheta| per unit group (median over samples) from local
        least squares of standardised w on theta over *feature-space* neighbours
        ``ind_w`` (pose-space neighbours would let poses bridge separate feature clusters).

        Groups: all linear columns together (one isotropic scale: x and y share metres),
        each periodic column alone. The local fit is the minimum-norm least-squares
        solution ignoring pose directions in which the neighbours spread less than 10 %
        of the main one: on a 1-D route through a 2-D position space the lateral
        direction is not observed, and fitting it would blow one column's scale up.
        A group whose median sensitivity is 0 (poses constant within most neighbourhoods,
        e.g. class labels as the target) gets 1 / its RMS neighbour difference, with a
        RuntimeWarning; a column that never varies keeps 0 (fit then raises)."""
        d = Theta.shape[1]
        self.theta_scale_ = np.ones(d)
        dT = self._pose_diff(Theta, Theta[ind_w])
        lin = [c for c in range(d) if c not in self._per]
        groups = ([lin] if lin else []) + [[c] for c in self._per]
        rms = np.empty((len(Theta), d))  # per-sample RMS of each group, so rcond is unit-free
        for g in groups:
            r = np.sqrt((dT[..., g] ** 2).sum(axis=2).mean(axis=1))
            rms[:, g] = np.maximum(r, np.finfo(float).tiny)[:, None]
        pinv = np.linalg.pinv(dT / rms[:, None, :], rcond=0.1)  # (n, d, k)
        norms = np.empty((len(Theta), len(groups)))
        for s in range(0, len(Theta), 4096):  # (chunk, k, m) differences: bounded memory
            sl = slice(s, s + 4096)
            Jt = pinv[sl] @ (Ws[sl, None, :] - Ws[ind_w[sl]]) / rms[sl, :, None]  # (., d, m)
            for i, g in enumerate(groups):
                norms[sl, i] = np.linalg.norm(Jt[:, g, :], ord=2, axis=(1, 2))
        scale = np.empty(d)
        for i, g in enumerate(groups):
            scale[g] = np.median(norms[:, i])
            if not scale[g[0]] > 0:  # e.g. a piecewise-constant target: the poses of most
                # feature-space neighbourhoods do not vary; use the global spread instead
                spread = float(np.sqrt((dT[..., g] ** 2).sum(axis=2).mean()))
                scale[g] = 1.0 / spread if spread > 0 else 0.0
                warnings.warn(f"theta_scale='auto': the poses of columns {g} do not vary "
                              "within most feature-space neighbourhoods (a piecewise-constant "
                              "target?); scaling them by their mean neighbour spread instead",
                              RuntimeWarning, stacklevel=3)
        return scale
