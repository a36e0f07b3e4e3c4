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

from localization.filtering.log_weights import normalise_log_weights
from localization.geometry import Array

__all__ = ["resample_and_inject", "seeded_resample"]


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


def resample_and_inject(X: Array, log_w: Array, resample: Callable[[Array], ArrayLike],
                        rng: np.random.Generator, n_inject: int = 0,
                        draw: Callable[[int], Array] | None = None) -> tuple[Array, Array]:
    """Resample particles ``X`` (N, d) by their log-weights ``log_w`` (N,) with the filterpy
    scheme ``resample`` (:func:`seeded_resample`), then replace ``n_inject`` random ones by
    ``draw(n_inject)`` (Augmented MCL's injections). Returns the particles (N, d) and which
    of them were injected (N,) bool."""
    p = np.exp(normalise_log_weights(log_w))
    X = np.asarray(X)[seeded_resample(resample, p / p.sum(), rng)]
    fresh = np.zeros(len(X), dtype=bool)
    if n_inject > 0 and draw is not None:
        slots = rng.choice(len(X), size=n_inject, replace=False)
        X[slots] = draw(n_inject)
        fresh[slots] = True
    return X, fresh
