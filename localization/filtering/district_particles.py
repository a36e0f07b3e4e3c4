"""The particle belief's likelihood and image proposals for a localizer of several maps.

With a :class:`~localization.districts.DistrictLocalizer` (duck-typed here: ``views_``,
``owners``, ``candidates``) every particle is weighed by the district whose cell holds it
(with an :class:`~localization.experiences.ExperienceLocalizer`, every particle by the look
the image resembles): the image's measurement by that district's maps at the particle's pose, with the
pose-equivalent R the districts share ("pose", "representation"), so the distances of
particles in different districts are on one scale. An image proposes psi* and the
retrieved training poses of every district whose psi* lies in its own region: look-alike
places in several districts all get particles, and the next images decide. An image no
district has a measurement of has none, as with one map (the belief keeps its weights).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering.image_proposals import ImageProposals
from localization.filtering.particle_likelihood import ParticleLikelihood, capped_log_likelihood
from localization.geometry import Array, wrap_angle

__all__ = ["DistrictLikelihood", "DistrictProposals", "check_measurement_noise", "image_models",
           "is_districted"]


def is_districted(localizer: Any) -> bool:
    """True for a localizer of several maps (one with ``local(pose)``)."""
    return callable(getattr(localizer, "local", None))


def check_measurement_noise(localizer: Any, measurement: str) -> None:
    """NotFittedError unless the localizer (one map, or a district of several) has the
    named model's R."""
    one = localizer.local(localizer.prior()[0]) if is_districted(localizer) else localizer
    one.measurement_model(measurement)


def image_models(localizer: Any, measurement: str, alpha: Array, gate_probability: float,
                 n_neighbors: int, proposal_noise: Array) -> tuple[Any, Any, int]:
    """The particle belief's likelihood, image proposals and feature width for a localizer
    of one map (:class:`ParticleLikelihood`, :class:`ImageProposals`) or of several."""
    if is_districted(localizer):
        return (DistrictLikelihood(localizer, measurement, alpha, gate_probability),
                DistrictProposals(localizer, n_neighbors, proposal_noise),
                len(localizer.views_) * localizer.n_features_)
    return (ParticleLikelihood(localizer, measurement, alpha, gate_probability),
            ImageProposals(localizer, n_neighbors, proposal_noise),
            len(localizer.regressor_.w_mean_))


class DistrictLikelihood:
    """:class:`ParticleLikelihood` of each district, each particle weighed by its own.

    ``measure(w)`` returns the image's features w themselves (the measurement depends on
    the district), or NaN when no district's maps have a measurement of it;
    ``distances(w, X)`` measures per district.
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
        """The features w (K m,): each district measures its own block. NaN (K m,) when
        the image lies outside every district's training domain (an occluded or unfamiliar
        view): as one map's NaN measurement, the belief keeps its weights, where a floor
        likelihood at every particle would read as a kidnap."""
        w = np.asarray(w, dtype=np.float64)
        views = self.localizer.views_
        if any(np.all(np.isfinite(part.measure(view.select(w))))
               for part, view in zip(self.parts, views, strict=True)):
            return w
        return np.full_like(w, np.nan)

    def distances(self, w: Array, X: Any) -> Array:
        """Squared Mahalanobis distances d2 (N,) of the image at the particles ``X`` (N, 3),
        each by the map that owns it (``localizer.owners``); NaN where that map is undefined."""
        X = np.asarray(X, dtype=np.float64)
        owner = self.localizer.owners(X, w)
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
        return capped_log_likelihood(self.distances(w, X), self.gate)


class DistrictProposals:
    """:class:`ImageProposals` of every district the image may show (see the module
    docstring); ``train_poses`` are all districts' training poses."""

    def __init__(self, localizer: Any, n_neighbors: int, noise: Array) -> None:
        self.localizer, self.noise = localizer, noise
        self.parts = [ImageProposals(v.localizer, n_neighbors, noise) for v in localizer.views_]
        self.train_poses = np.vstack([p.train_poses for p in self.parts])
        self._last: tuple[bytes, list[int]] | None = None  # the last image's districts

    def _shown(self, w: Array) -> list[tuple[ImageProposals, Array]]:
        """(proposals, block of w) of the districts whose psi*(w) lies in their own region
        (every district when none does). A step asks for the same image's districts more
        than once (injection, confirmation): they are kept for the last image."""
        views, key = self.localizer.views_, np.asarray(w, dtype=np.float64).tobytes()
        if self._last is None or self._last[0] != key:
            ks = [k for _, k, _ in self.localizer.candidates(w)] or list(range(len(views)))
            self._last = (key, ks)
        return [(self.parts[k], views[k].select(w)) for k in self._last[1]]

    def __call__(self, w: Array) -> Array:
        """psi* and the retrieved training poses (k, 3) of each district the image may show:
        look-alike places in several districts all get particles, and the next images
        decide."""
        return np.vstack([part(wk) for part, wk in self._shown(w)])

    def neighbours(self, w: Array) -> Array:
        """The retrieved training poses of each district the image may show."""
        return np.vstack([part.neighbours(wk) for part, wk in self._shown(w)])

    def agreement(self, w: Array, pose: Array, radius: float, heading_scale: float) -> float:
        """Share of :meth:`neighbours` within ``radius`` of ``pose`` (as
        :meth:`ImageProposals.agreement`): low while several districts look alike."""
        d = self.neighbours(w) - pose
        d2 = d[:, 0] ** 2 + d[:, 1] ** 2 + (heading_scale * wrap_angle(d[:, 2])) ** 2
        return float(np.mean(d2 < radius ** 2))

    def jitter(self, centres: Array, n: int, rng: np.random.Generator) -> Array:
        return self.parts[0].jitter(centres, n, rng)
