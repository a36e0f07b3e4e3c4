"""The particle belief's likelihood and image proposals for a localizer of several maps.

With a :class:`~localization.districts.DistrictLocalizer` (duck-typed here: ``views_``,
``districts_of``, ``candidates``) every particle is weighed by the district whose cell holds
it: the image's measurement by that district's maps at the particle's pose, with the
pose-equivalent R the districts share ("pose", "representation"), so the distances of
particles in different districts are on one scale. An image proposes the poses of the
district chosen as for a start without a pose (psi* in its own region, least novel), psi*
first, then that district's retrieved training poses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering.image_proposals import ImageProposals
from localization.filtering.particle_likelihood import ParticleLikelihood
from localization.geometry import Array

__all__ = ["DistrictLikelihood", "DistrictProposals", "is_districted"]


def is_districted(localizer: Any) -> bool:
    """True for a localizer of several maps (one with ``local(pose)``)."""
    return callable(getattr(localizer, "local", None))


class DistrictLikelihood:
    """:class:`ParticleLikelihood` of each district, each particle weighed by its own.

    ``measure(w)`` returns the image's features w themselves (the measurement depends on
    the district); ``distances(w, X)`` measures per district.
    """

    def __init__(self, localizer: Any, measurement: str, alpha: Array,
                 gate_probability: float) -> None:
        if measurement == "features":
            raise ValueError("a DistrictLocalizer's particles use the 'pose' or "
                             "'representation' model (the features' spaces differ between "
                             "districts)")
        self.localizer, self.measurement = localizer, measurement
        self.parts = [ParticleLikelihood(v.localizer, measurement, alpha, gate_probability)
                      for v in localizer.views_]
        self.R, self.gate = self.parts[0].R, self.parts[0].gate

    def measure(self, w: Array) -> Array:
        """The features w (K m,): each district measures its own block."""
        return np.asarray(w, dtype=np.float64)

    def distances(self, w: Array, X: Any) -> Array:
        """Squared Mahalanobis distances d2 (N,) of the image at the particles ``X`` (N, 3),
        each by its district; NaN where that district's maps are undefined."""
        X = np.asarray(X, dtype=np.float64)
        owner = self.localizer.districts_of(X)
        d2 = np.full(len(X), np.nan)
        for k in np.unique(owner):
            rows = owner == k
            part, view = self.parts[k], self.localizer.views_[k]
            z = part.measure(view.select(w))
            if np.all(np.isfinite(z)):
                d2[rows] = part.distances(z, X[rows])
        return d2

    def log_likelihood(self, w: Array, X: Any) -> Array:
        """``log L_i = -0.5 min(d2_i, gate)`` (N,): never NaN."""
        return -0.5 * np.minimum(np.nan_to_num(self.distances(w, X), nan=np.inf), self.gate)


class DistrictProposals:
    """:class:`ImageProposals` of the district an image points at (see the module
    docstring); ``train_poses`` are all districts' training poses."""

    def __init__(self, localizer: Any, n_neighbors: int, noise: Array) -> None:
        self.localizer, self.noise = localizer, noise
        self.parts = [ImageProposals(v.localizer, n_neighbors, noise) for v in localizer.views_]
        self.train_poses = np.vstack([p.train_poses for p in self.parts])

    def _part(self, w: Array) -> tuple[ImageProposals | None, Array]:
        found = self.localizer.candidates(w)
        if not found:
            return None, w
        k = found[0][1]
        return self.parts[k], self.localizer.views_[k].select(w)

    def __call__(self, w: Array) -> Array:
        """psi* of the chosen district and its retrieved training poses (k, 3); every
        district's retrieval when no district's psi* lies in its region."""
        part, wk = self._part(w)
        if part is not None:
            return part(wk)
        return np.vstack([p.neighbours(v.select(w))
                          for p, v in zip(self.parts, self.localizer.views_)])

    def neighbours(self, w: Array) -> Array:
        part, wk = self._part(w)
        if part is None:
            return np.zeros((0, 3))
        return part.neighbours(wk)

    def agreement(self, w: Array, pose: Array, radius: float, heading_scale: float) -> float:
        part, wk = self._part(w)
        return 0.0 if part is None else part.agreement(wk, pose, radius, heading_scale)

    def jitter(self, centres: Array, n: int, rng: np.random.Generator) -> Array:
        return self.parts[0].jitter(centres, n, rng)
