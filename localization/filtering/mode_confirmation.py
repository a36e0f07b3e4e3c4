"""Is the particles' dominant mode confirmed by the images? (:class:`ParticleBelief`'s rule.)

Particles seeded from images (a start without a pose, an Augmented MCL injection) are a guess
that an image can repeat in every place that looks like it, and resampling can gather them
all on one of those places: weight alone does not make such a mode known. It is confirmed
once at least ``share`` of each image's retrieved training poses lie within the mode kernel
of its mean on ``steps`` frames in a row, and loses that after ``unconfirm_steps`` frames in
a row that do not agree (None: never). docs/method.md §13.2 gives the tuning-city numbers.
"""

from __future__ import annotations

from localization._validation import check_int, check_real

__all__ = ["ModeConfirmation"]


class ModeConfirmation:
    """Counts the frames whose retrieved neighbours agree with the dominant mode.

    Parameters
    ----------
    share : float in [0, 1]
        Share of an image's retrieved neighbours near the mode for the frame to agree
        (``confirm_share``).
    steps : int
        Agreeing frames in a row that confirm (``confirm_steps``, >= 1).
    unconfirm_steps : int or None
        Disagreeing frames in a row that withdraw a confirmation (>= 1; None: never).

    Attributes
    ----------
    confirmed : bool
    agreeing, disagreeing : int
        Frames in a row that agreed / did not.
    """

    def __init__(self, share: float = 0.5, steps: int = 2,
                 unconfirm_steps: int | None = 5) -> None:
        self.share = check_real(share, "confirm_share", low=0.0, high=1.0)
        self.steps = check_int(steps, "confirm_steps", low=1)
        self.unconfirm_steps = None if unconfirm_steps is None else \
            check_int(unconfirm_steps, "unconfirm_steps", low=1)
        self.reset(False)

    def reset(self, confirmed: bool) -> None:
        """Start over: ``confirmed`` (a given start pose needs no image to confirm it)."""
        self.confirmed, self.agreeing, self.disagreeing = bool(confirmed), 0, 0

    def withdraw(self) -> None:
        """Particles were seeded from images again: the mode is a guess until confirmed."""
        self.confirmed, self.agreeing = False, 0

    def update(self, agreement: float) -> bool:
        """One frame whose retrieved neighbours have this ``agreement`` (the share near the
        mode) with the dominant mode; returns whether the mode is confirmed after it."""
        if self.confirmed and self.unconfirm_steps is None:
            return True
        ok = agreement >= self.share
        self.agreeing, self.disagreeing = (self.agreeing + 1, 0) if ok else \
            (0, self.disagreeing + 1)
        if self.confirmed:
            self.confirmed = self.disagreeing < self.unconfirm_steps
        else:
            self.confirmed = self.agreeing >= self.steps
        return self.confirmed
