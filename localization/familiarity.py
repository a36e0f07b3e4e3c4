"""Image familiarity: whether the recent images look like the images the map was made from.

A belief on the wrong map (another city's localizer, ``allow_other_city=True``; a city that
has changed) still finds places there that its images fit well enough, and says "tracking"
while it is metres off. The images themselves say which map they belong to. The novelty of
an image's features ``w`` is their distance from the map's learned feature manifold,
``u(w) = |w - g_u(r*(w))|`` (reduce-then-recover, :meth:`GSERegressor.novelty <localization.gse.GSERegressor.novelty>`),
and its *relative* novelty is ``u(w) / u_ref``, with ``u_ref`` the median novelty of an
evenly spaced sample of the map's own training images. :class:`Familiarity` keeps the
relative novelty of the last ``window`` images; while their median exceeds ``threshold`` the
images are *unfamiliar*, and a belief that says "tracking" is reported "doubtful" instead
(``BeliefWrapper(familiar_novelty=threshold)``). An image outside the training domain (NaN)
counts as infinitely novel.

Measured on tuning cities 13-14 (docs/benchmarks.md §11 "Stop 76"): images rated by their own
city's map read about 1.7-4.2 (10th-90th percentile), by the other city's 6.3-13.7.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_int, check_real

__all__ = ["FAMILIAR_WINDOW", "Familiarity", "novelty_scale"]

#: images whose median relative novelty decides (1 s at 10 Hz)
FAMILIAR_WINDOW = 10
_SAMPLE = 500  # training images in the median novelty


def novelty_scale(regressor: Any, sample: int = _SAMPLE) -> float:
    """``u_ref``: the median novelty of ``sample`` evenly spaced training images of a fitted
    :class:`~localization.gse.GSERegressor` (:meth:`~localization.gse.GSERegressor.training_novelty`)."""
    return float(max(np.nanmedian(regressor.training_novelty(sample)), 1e-12))


class Familiarity:
    """The relative novelty of the last ``window`` images (see the module docstring).

    Parameters
    ----------
    regressor : GSERegressor
        The map's fitted regressor (``localizer.regressor_``).
    threshold : float
        Median relative novelty above which the images are unfamiliar (> 0).
    window : int
        Images in the median (>= 1).

    Attributes
    ----------
    scale_ : float
        ``u_ref``, the median novelty of the map's training images.
    novelty : float
        The latest image's relative novelty (inf outside the training domain; NaN before one).
    """

    def __init__(self, regressor: Any, threshold: float, window: int = FAMILIAR_WINDOW) -> None:
        self.regressor = regressor
        self.threshold = check_real(threshold, "familiar_novelty", low=0.0, low_open=True)
        self.window = check_int(window, "window", low=1)
        self.scale_ = novelty_scale(regressor)
        self.reset()

    def reset(self) -> None:
        """Forget the images (a new episode)."""
        self._recent: deque[float] = deque(maxlen=self.window)
        self.novelty = float("nan")

    def update(self, w: ArrayLike) -> float:
        """Add the features ``w`` (m,) of the next image; its relative novelty."""
        u = float(self.regressor.novelty(np.asarray(w, dtype=np.float64)[None])[0])
        self.novelty = u / self.scale_ if np.isfinite(u) else float("inf")
        self._recent.append(self.novelty)
        return self.novelty

    @property
    def familiar(self) -> bool:
        """Whether the median relative novelty of the recent images is at most the threshold
        (True before any image)."""
        return not self._recent or float(np.median(self._recent)) <= self.threshold

    def status(self, belief_status: str) -> str:
        """``belief_status``, "doubtful" instead of "tracking" while the images are unfamiliar."""
        return "doubtful" if belief_status == "tracking" and not self.familiar else belief_status

