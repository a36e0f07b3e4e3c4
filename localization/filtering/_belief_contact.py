"""What a contact with the city does to the EKF belief (one mixin, the rules of
:class:`~localization.filtering.belief.BeliefFilter` in one place): "lost" for a while after a
contact where the map has room around the belief, or after a second contact soon after one
while not "tracking"; a contact with a known bearing also moves the mean to the nearest pose
at which the map explains it (:mod:`~localization.filtering.map_contact`)."""

from __future__ import annotations

from typing import Any

from localization.filtering.map_contact import (
    CONTACT_LOST_STEPS,
    REPEAT_CONTACT_STEPS,
    contact_contradicts,
    contact_projection,
)

__all__ = ["BeliefContactMixin"]


class BeliefContactMixin:
    """The contact rules of :class:`~localization.filtering.belief.BeliefFilter` (which
    holds the attributes used here)."""

    ekf: Any
    free_space: Any
    project_contacts: bool
    belief_status: str
    _bumped: int
    _since_contact: int

    def _contact(self, kinds: frozenset[str], bearing: float | None) -> None:
        """This step's contact of ``kinds`` (empty: none) at ``bearing`` (None: unknown)."""
        self._bumped = max(self._bumped - 1, 0)
        contradicts = "city" in kinds and self.free_space is not None and contact_contradicts(
            self.free_space, self.ekf.x, self.ekf.P, bearing)
        if contradicts and self.project_contacts and bearing is not None:
            self._project(bearing)
        if contradicts or ("city" in kinds and self._repeated_contact()):
            self._bumped = CONTACT_LOST_STEPS
        self._since_contact = 0 if "city" in kinds else self._since_contact + 1

    def _project(self, bearing: float) -> None:
        """Move the mean to the nearest pose that explains a contact at ``bearing``."""
        pose = contact_projection(self.free_space, self.ekf.x, self.ekf.P, bearing)
        if pose is not None:
            self.ekf.x = pose

    def _repeated_contact(self) -> bool:
        """A contact with the city this step is a second one within ``REPEAT_CONTACT_STEPS``
        (after a step without) while the belief is not "tracking"."""
        return (0 < self._since_contact <= REPEAT_CONTACT_STEPS
                and self.belief_status != "tracking")
