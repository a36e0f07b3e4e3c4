"""What the pose belief needs from a fitted localizer: the :class:`Localizer` protocol
(an :class:`~localization.localizer.AppearanceLocalizer`, or a
:class:`~localization.districts.DistrictLocalizer` of several maps) and its check."""

from __future__ import annotations

from typing import Any, Protocol

from numpy.typing import ArrayLike

from localization.geometry import Array

__all__ = ["Localizer", "check_localizer"]


class Localizer(Protocol):
    """What the belief needs from a fitted localizer (e.g.
    :class:`~localization.localizer.AppearanceLocalizer`): measurement models, the noise
    model and an initial belief from one image's features.

    A localizer of several maps (:class:`~localization.districts.DistrictLocalizer`) also
    has ``local(x)``: the localizer in charge at pose x. The belief then measures each
    image, and takes its measurement model, from the one in charge at its prior mean (a
    hand-over between districts); ``initial_belief`` and ``measure(w, "pose")`` need no
    pose."""

    control_gain_: Any

    def consistency(self, measurement: str) -> Array: ...
    def measurement_model(self, measurement: str, alpha: ArrayLike | None = None,
                          **options: Any) -> Any: ...
    def process_noise(self, pose: ArrayLike, alpha: ArrayLike | None = None) -> Array: ...
    def initial_belief(self, w: ArrayLike) -> tuple[Array, Array]: ...
    def prior(self) -> tuple[Array, Array]: ...
    def measure(self, w: ArrayLike, measurement: str) -> Array: ...


def check_localizer(localizer: object) -> Localizer:
    """``localizer`` if it is a :class:`Localizer` (TypeError otherwise); a localizer that can
    tell (``check_ready``) raises its own error when it is not fitted or has no noise model."""
    names = ("measurement_model", "process_noise", "initial_belief", "measure", "consistency")
    if not all(callable(getattr(localizer, m, None)) for m in names):
        raise TypeError("localizer must be a fitted localizer (e.g. AppearanceLocalizer), got "
                        f"{type(localizer).__name__}")
    check_ready = getattr(localizer, "check_ready", None)
    if callable(check_ready):
        check_ready()
    return localizer  # type: ignore[return-value]
