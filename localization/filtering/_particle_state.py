"""What a :class:`~localization.filtering.particles.ParticleBelief` reports (a mixin): the
weights, the effective sample size, the dominant mode's mean and covariance (its tracker's,
with ``track_mode``) and every hypothesis.

The host class provides ``particles``, ``log_weights``, ``modes``, ``tracker`` and
``confirmation``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering._modes import Mode
from localization.geometry import Array

__all__ = ["ParticleStateMixin"]


class ParticleStateMixin:
    """The read-only summaries of a particle belief."""

    particles: Array | None
    log_weights: Array | None
    modes: list[Mode]
    tracker: Any
    confirmation: Any

    @property
    def confirmed(self) -> bool:
        """Have the images confirmed the dominant mode since particles were seeded from
        them (:class:`~localization.filtering.mode_confirmation.ModeConfirmation`)?"""
        return self.confirmation.confirmed

    @property
    def weights(self) -> Array:
        """Normalised weights (N,)."""
        self._check()
        return np.exp(self.log_weights)  # type: ignore[arg-type]

    @property
    def ess(self) -> float:
        """Effective sample size ``1 / sum w_i^2``."""
        return float(1.0 / np.sum(self.weights ** 2))

    @property
    def pose_mean(self) -> Array:
        """Mean (3,) of the dominant mode (its EKF's with ``track_mode``)."""
        self._check()
        return self.modes[0].mean.copy() if self.tracker is None else self.tracker.mean

    @property
    def pose_cov(self) -> Array:
        """Covariance (3, 3) of the dominant mode (heading residuals wrapped)."""
        self._check()
        return self.modes[0].cov.copy() if self.tracker is None else self.tracker.cov

    x, P = pose_mean, pose_cov  # BeliefFilter's names

    @property
    def hypotheses(self) -> dict[str, Array]:
        """The modes, heaviest first: "weights" (k,), "means" (k, 3), "covs" (k, 3, 3)."""
        self._check()
        return {"weights": np.array([m.weight for m in self.modes]),
                "means": np.array([m.mean for m in self.modes]),
                "covs": np.array([m.cov for m in self.modes])}

    def _check(self) -> None:
        if self.particles is None:
            raise RuntimeError("the belief is not initialised: call reset() first")
