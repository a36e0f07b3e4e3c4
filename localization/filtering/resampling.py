"""Resampling with ``filterpy.monte_carlo``'s schemes under a numpy ``Generator``.

filterpy's schemes (systematic, stratified, residual, multinomial) draw from numpy's global
random state. :func:`seeded_resample` seeds that state from the caller's generator for the
call and restores it afterwards, so a seeded filter gives the same run and leaves the
user's global state alone.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array

__all__ = ["seeded_resample"]


def seeded_resample(resample: Callable[[Array], ArrayLike], p: Array,
                    rng: np.random.Generator) -> Array:
    """Indexes (N,) drawn by the filterpy scheme ``resample`` from normalised weights
    ``p`` (N,), its global draws seeded from ``rng``."""
    state = np.random.get_state()
    try:
        np.random.seed(int(rng.integers(2 ** 32)))
        idx = np.asarray(resample(p), dtype=np.intp)
    finally:
        np.random.set_state(state)
    return np.minimum(idx, len(p) - 1)  # a cumulative sum a hair below 1
