"""The particle belief's status: what :class:`~localization.filtering.particles.ParticleBelief`
tells an agent about itself after each step (one mixin, the rules in one place)."""

from __future__ import annotations

from typing import Any

from localization.filtering.belief import LOST_AFTER_MISSES

__all__ = ["PARTICLE_STATUSES", "ParticleStatusMixin"]

#: "initial" after reset (``belief_status`` then: see ``_start_status``); "out_of_domain": the
#: image has no measurement (weights kept);
#: "lost": w_fast < lost_ratio w_slow (the images are far less likely than usual);
#: "doubtful": this image alone is far less likely than usual (w_avg < doubt_ratio w_slow:
#: an outlier frame, or the first sign of a kidnap), or (``track_mode``) the reported EKF
#: holds its pose against most particles;
#: "relocalizing": Augmented MCL injected particles this step; "ambiguous": the dominant mode holds less
#: than ``confident_weight``, or no image has confirmed it since the particles were seeded
#: from images (``confirm_share``); "tracking": otherwise.
#: ``belief_status`` is what an agent steers by: the step's status, except on an image with no
#: measurement, where the belief coasts (:meth:`ParticleBelief._coast_status`): "lost" as
#: above, "ambiguous" while the dominant mode is light or unconfirmed, "doubtful" from the
#: ``LOST_AFTER_MISSES``-th such step in a row (as the EKF's), else as it was.
PARTICLE_STATUSES = ("initial", "tracking", "ambiguous", "doubtful", "relocalizing", "lost",
                     "out_of_domain")


class ParticleStatusMixin:
    """The status rules of :class:`~localization.filtering.particles.ParticleBelief` (which
    holds the state they read: ``_bumped``, ``amcl``, ``lost_ratio``, ``doubt_ratio``,
    ``modes``, ``confident_weight``, ``confirmed``, ``_recovering``, ``_misses``,
    ``belief_status``)."""

    _bumped: int
    _recovering: bool
    _misses: int
    amcl: Any
    modes: Any
    lost_ratio: float
    doubt_ratio: float
    confident_weight: float
    belief_status: str

    def _lost(self) -> bool:
        """After a contradicting contact, or while ``w_fast < lost_ratio w_slow``."""
        return bool(self._bumped) or self.amcl.w_fast < self.lost_ratio * self.amcl.w_slow

    def _ambiguous(self) -> bool:
        """The dominant mode holds less than ``confident_weight``, or no image confirmed it."""
        return self.modes[0].weight < self.confident_weight or not self.confirmed

    def _start_status(self, mode: str, known: bool) -> str:
        """``belief_status`` after ``reset``: "tracking" from a given pose, "relocalizing"
        from a global start, and from the first image as after a step: "ambiguous" while its
        mode is light or unconfirmed (one image cannot confirm it at ``confirm_steps`` >= 2)."""
        if known:
            return "tracking"
        if mode == "global":
            return "relocalizing"
        return "ambiguous" if self._ambiguous() else "tracking"

    def _status(self, w_avg: float) -> str:
        if self._lost():
            return "lost"
        if self._recovering:
            return "relocalizing"
        if w_avg < self.doubt_ratio * self.amcl.w_slow:
            return "doubtful"
        if self._ambiguous():
            return "ambiguous"
        return "tracking"

    def _coast_status(self) -> str:
        """The belief's status on a step whose image had no measurement (an occluded or
        unfamiliar view: the particles only moved): see ``PARTICLE_STATUSES``."""
        if self._lost():
            return "lost"
        if self._ambiguous():
            return "ambiguous"
        if self._misses >= LOST_AFTER_MISSES and self.belief_status == "tracking":
            return "doubtful"
        return self.belief_status
