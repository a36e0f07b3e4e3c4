"""What a contact with the city does to the particle belief (one mixin, the rules of
:class:`~localization.filtering.particles.ParticleBelief` in one place): weigh the particles
by the map (:func:`~localization.filtering.map_contact.weigh_contact`) and, when the contact
contradicts them, move a share to the walls it could have come from
(:mod:`~localization.filtering.contact_spread`)."""

from __future__ import annotations

from typing import Any

from localization.filtering.map_contact import CONTACT_LOST_STEPS, weigh_contact
from localization.filtering.resampling import resample_and_inject
from localization.geometry import Array

__all__ = ["ParticleContactMixin"]


class ParticleContactMixin:
    """The contact rules of :class:`~localization.filtering.particles.ParticleBelief` (which
    holds the attributes used here)."""

    particles: Array
    log_weights: Array
    weights: Array
    free_space: Any
    spread: Any
    tracker: Any
    resample: Any
    rng: Any
    _bumped: int
    _fresh: Array

    def _bump(self, kinds: frozenset[str], bearing: float | None) -> Array | float:
        """The log-likelihood (N,) of a contact with the city at the particles (0 without);
        "lost" for ``CONTACT_LOST_STEPS`` steps after one that contradicts the belief, which
        first moves a share of the particles to where the map explains it."""
        self._bumped = max(self._bumped - 1, 0)
        if "city" not in kinds or self.free_space is None:
            return 0.0
        log_B, contradicted = weigh_contact(self.free_space, self.particles, self.log_weights,
                                            bearing)
        if contradicted and self._spread(bearing):
            log_B, _ = weigh_contact(self.free_space, self.particles, self.log_weights, bearing)
        self._bumped = CONTACT_LOST_STEPS if contradicted else self._bumped
        return log_B

    def _spread(self, bearing: float | None) -> bool:
        """Resample, moving a share of the particles to walls (:attr:`spread`); whether any
        were. The moved ones count as injected (not in this step's ``w_avg``)."""
        n = self.spread.size(len(self.particles), self.rng)
        if n == 0:
            return False
        X, w = self.particles, self.weights
        X, self._fresh = resample_and_inject(
            X, self.log_weights, self.resample, self.rng, n,
            lambda k: self.spread.draw(self.free_space, X, w, bearing, self.rng, k))
        self._set(X)
        if self.tracker is not None:
            self.tracker.contradict()
        return True
