"""ImageProposals: the poses one image suggests (Augmented MCL's injections from appearance).

psi*(w) (when in the training domain) and the training poses of the ``n_neighbors``
nearest training images in feature space (retrieval on the GSE's standardised training
features), jittered by a body-frame noise. A laser AMCL injects uniformly; an image can say
where to look.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sklearn.neighbors import NearestNeighbors

from localization.filtering.particle_motion import sample_body_noise
from localization.geometry import Array

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
        reg = localizer.regressor_
        self.localizer, self.noise = localizer, noise
        self.train_poses = localizer.from_model(reg.theta_)
        m = len(reg.w_mean_)
        self._retrieval = NearestNeighbors(n_neighbors=min(int(n_neighbors), len(reg.theta_)))
        self._retrieval.fit(reg.gse_.Z_[:, :m])  # standardised training features

    def __call__(self, w: Array) -> Array:
        """Poses (k, 3) the features ``w`` (m,) suggest: psi*(w) first (when in domain),
        then the training poses of the nearest training images."""
        reg = self.localizer.regressor_
        ws = ((w - reg.w_mean_) / reg.w_scale_)[None]
        idx = self._retrieval.kneighbors(ws, return_distance=False)[0]
        psi = self.localizer.measure(w, "pose")[None]
        return np.vstack([psi[np.all(np.isfinite(psi), axis=1)], self.train_poses[idx]])

    def jitter(self, centres: Array, n: int, rng: np.random.Generator) -> Array:
        """``n`` poses (n, 3): centres (k, 3) drawn with replacement plus body-frame noise."""
        X = centres[rng.integers(len(centres), size=n)]
        return X + sample_body_noise(X[:, 2], self.noise, rng)
