"""Modes of a weighted particle set of poses: circular statistics and mode finding.

A particle set may hold several distant hypotheses; its overall mean can lie between
them, in a building. :func:`find_modes` summarises each hypothesis separately:

1. seed a mode at the heaviest grid cell (computed once per call) of the remaining weight (cells of ``radius``
   metres and ``radius / heading_scale`` radians);
2. weighted mean-shift with a flat kernel: the members are the remaining particles within
   distance ``radius`` of the mean, in the metric
   ``d^2 = dx^2 + dy^2 + (heading_scale * wrap(dyaw))^2``; the mean is their weighted
   mean (heading: the circular mean), repeated until the members stop changing;
3. the mode's weight, mean and covariance (wrapped heading residuals) are those of its
   members, which are then removed; repeat while weight remains.

Cost ``O(N)`` per mean-shift iteration and mode (no N x N distances).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array, wrap_angle

__all__ = ["Mode", "cells", "circular_mean", "find_modes", "weighted_pose_stats"]

_COV_FLOOR = np.diag([1e-6, 1e-6, 1e-8])  # a single-particle mode still has a valid covariance


@dataclass(frozen=True)
class Mode:
    """One hypothesis: total weight of its particles, mean pose (3,), covariance (3, 3)."""

    weight: float
    mean: Array
    cov: Array


def circular_mean(angles: ArrayLike, weights: ArrayLike | None = None) -> float:
    """Weighted mean direction ``atan2(sum w sin a, sum w cos a)`` in (-pi, pi]; 0 when the
    resultant vanishes (uniform headings)."""
    a = np.asarray(angles, dtype=np.float64)
    w = np.ones_like(a) if weights is None else np.asarray(weights, dtype=np.float64)
    s, c = float(w @ np.sin(a)), float(w @ np.cos(a))
    return float(wrap_angle(np.arctan2(s, c))) if np.hypot(s, c) > 1e-300 else 0.0


def weighted_pose_stats(X: ArrayLike, w: ArrayLike) -> tuple[Array, Array]:
    """Weighted mean (3,) and covariance (3, 3) of poses (n, 3), heading on the circle:
    the circular mean, and residuals ``wrap(yaw - mean)`` in the covariance."""
    X, w = np.asarray(X, dtype=np.float64), np.asarray(w, dtype=np.float64)
    w = w / w.sum()
    mean = np.array([w @ X[:, 0], w @ X[:, 1], circular_mean(X[:, 2], w)])
    d = X - mean
    d[:, 2] = wrap_angle(d[:, 2])
    return mean, (d * w[:, None]).T @ d + _COV_FLOOR


def _distance2(X: Array, centre: Array, heading_scale: float) -> Array:
    dyaw = wrap_angle(X[:, 2] - centre[2])
    return (X[:, 0] - centre[0]) ** 2 + (X[:, 1] - centre[1]) ** 2 + (heading_scale * dyaw) ** 2


def cells(X: Array, radius: float, heading_scale: float) -> Array:
    """Grid-cell label (n,) of each pose: cells of ``radius`` m and ``radius / heading_scale``
    rad, numbered 0.. in order of first appearance of their key."""
    ix = np.floor(X[:, 0] / radius).astype(np.int64)
    iy = np.floor(X[:, 1] / radius).astype(np.int64)
    ih = np.floor((X[:, 2] + np.pi) * heading_scale / radius).astype(np.int64)
    key = ((ix - ix.min()) * (iy.max() - iy.min() + 1) + (iy - iy.min())) * (ih.max() + 1) + ih
    return np.unique(key, return_inverse=True)[1].ravel()


def find_modes(X: ArrayLike, w: ArrayLike, radius: float = 1.0, heading_scale: float = 2.0,
               max_modes: int = 5, min_weight: float = 0.01, max_iter: int = 20) -> list[Mode]:
    """The modes of particles ``X`` (n, 3) with weights ``w`` (n,), heaviest first.

    Parameters
    ----------
    X : (n, 3) poses; w : (n,) non-negative weights (normalised here).
    radius : float
        Kernel radius (m) of a mode in the metric of the module docstring.
    heading_scale : float
        Metres a radian of heading counts as.
    max_modes : int
        At most this many modes.
    min_weight : float
        Stop when less than this weight remains unassigned.
    max_iter : int
        Mean-shift iterations per mode.

    Returns
    -------
    list of Mode, sorted by decreasing weight; weights sum to <= 1 (particles left over
    when ``max_modes`` are found are in no mode).
    """
    X, w = np.asarray(X, dtype=np.float64), np.asarray(w, dtype=np.float64)
    total = w.sum()
    if not (total > 0 and np.all(w >= 0) and np.all(np.isfinite(w))):
        raise ValueError("w must be finite, non-negative and not all zero")
    left = w / total
    labels = cells(X, radius, heading_scale)
    idx = np.flatnonzero(left > 0)  # the particles no mode holds yet (weight > 0)
    modes: list[Mode] = []
    while len(modes) < max_modes and left[idx].sum() >= min_weight:
        members = _mean_shift(X[idx], left[idx], labels[idx], radius, heading_scale, max_iter)
        mean, cov = weighted_pose_stats(X[idx[members]], left[idx[members]])
        modes.append(Mode(float(left[idx[members]].sum()), mean, cov))
        idx = idx[~members]
    return sorted(modes, key=lambda m: -m.weight)


def _mean_shift(X: Array, w: Array, labels: Array, radius: float, heading_scale: float,
                max_iter: int) -> Array:
    """Members (n,) bool of one mode of the particles ``X`` (n, 3) of weights ``w`` > 0:
    seeded at the heaviest cell of ``labels``, shifted to its flat-kernel mean."""
    members = labels == int(np.argmax(np.bincount(labels, weights=w)))
    for _ in range(max_iter):
        new = _distance2(X, _weighted_mean(X[members], w[members]), heading_scale) <= radius ** 2
        if not new.any() or np.array_equal(new, members):
            break
        members = new
    return members


def _weighted_mean(X: Array, w: Array) -> Array:
    """The weighted mean pose (3,) of ``X`` (n, 3), heading on the circle (the mean of
    :func:`weighted_pose_stats`, without its covariance)."""
    s, c = float(w @ np.sin(X[:, 2])), float(w @ np.cos(X[:, 2]))
    yaw = float(wrap_angle(np.arctan2(s, c))) if np.hypot(s, c) > 1e-300 else 0.0
    return np.array([w @ X[:, 0], w @ X[:, 1], yaw]) / np.array([w.sum(), w.sum(), 1.0])
