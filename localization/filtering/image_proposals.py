"""ImageProposals: the poses one image suggests (Augmented MCL's injections from appearance).

psi*(w) (when in the training domain) and the training poses of the ``n_neighbors``
nearest training images in feature space (retrieval on the GSE's standardised training
features, with the GSE's own index: :meth:`GSERegressor.kneighbors`), jittered by a
body-frame noise. A laser AMCL injects uniformly; an image can say
where to look.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering.particle_motion import sample_body_noise
from localization.geometry import Array, wrap_angle

__all__ = ["ImageProposals"]


class ImageProposals:
    """Pose proposals of an image for a fitted localizer.

    Parameters
    ----------
    localizer : AppearanceLocalizer
        Fitted.
    n_neighbors : int
        Training images retrieved per image.
    noise : ndarray (3, 3)
        Body-frame covariance of the jitter.

    Attributes
    ----------
    train_poses : ndarray (n, 3)
        The localizer's training poses.
    """

    def __init__(self, localizer: Any, n_neighbors: int, noise: Array) -> None:
        self.localizer, self.noise = localizer, noise
        self.n_neighbors = int(n_neighbors)
        self.train_poses = localizer.from_model(localizer.regressor_.theta_)

    def __call__(self, w: Array) -> Array:
        """Poses (k, 3) the features ``w`` (m,) suggest: psi*(w) first (when in domain),
        then the training poses of the nearest training images."""
        psi = self.localizer.measure(w, "pose")[None]
        return np.vstack([psi[np.all(np.isfinite(psi), axis=1)], self.neighbours(w)])

    def neighbours(self, w: Array) -> Array:
        """Training poses (n_neighbors, 3) of the training images nearest to ``w`` (m,)."""
        ind = self.localizer.regressor_.kneighbors(w[None], self.n_neighbors)[1][0]
        return self.train_poses[ind]

    def agreement(self, w: Array, pose: Array, radius: float, heading_scale: float) -> float:
        """Share (float in [0, 1]) of the image's retrieved neighbours within ``radius`` of
        ``pose`` (3,) in the metric ``dx^2 + dy^2 + (heading_scale dyaw)^2``: near 1 when
        the image points at ``pose`` alone, about 1 / (number of twins) when it looks the
        same in several places."""
        d = self.neighbours(w) - pose
        d2 = d[:, 0] ** 2 + d[:, 1] ** 2 + (heading_scale * wrap_angle(d[:, 2])) ** 2
        return float(np.mean(d2 < radius ** 2))

    def jitter(self, centres: Array, n: int, rng: np.random.Generator) -> Array:
        """``n`` poses (n, 3): centres (k, 3) drawn with replacement plus body-frame noise."""
        X = centres[rng.integers(len(centres), size=n)]
        return X + sample_body_noise(X[:, 2], self.noise, rng)
