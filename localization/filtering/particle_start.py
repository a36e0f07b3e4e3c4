"""Where a particle belief starts: around a known pose, or over the free space.

:meth:`~localization.filtering.particles.ParticleBelief.reset` draws its particles here
(besides the image's proposals, :mod:`localization.filtering.image_proposals`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array

__all__ = ["DEFAULT_P0", "SampleFree", "free_particles", "gaussian_particles"]

#: ``sample_free(n, rng) -> (n, 3)``: free poses (e.g. :func:`~.free_space.city_sampler`)
SampleFree = Callable[[int, np.random.Generator], ArrayLike]
#: covariance of a start around a known pose when none is given (the EKF's too)
DEFAULT_P0 = np.diag([0.01, 0.01, 0.001])
DEFAULT_P0.setflags(write=False)


def gaussian_particles(x0: ArrayLike, P0: ArrayLike | None, n: int,
                       rng: np.random.Generator) -> Array:
    """``n`` draws (n, 3) of ``N(x0, P0)`` (``P0`` default :data:`DEFAULT_P0`); a ValueError
    naming ``x0`` and ``P0`` unless they are a finite (3,) pose and a (3, 3) matrix."""
    x0 = np.asarray(x0, dtype=np.float64)
    P0 = DEFAULT_P0 if P0 is None else np.asarray(P0, dtype=np.float64)
    if x0.shape != (3,) or P0.shape != (3, 3) or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be a finite (3,) pose and P0 (3, 3), got {x0.shape} and "
                         f"{P0.shape}")
    return rng.multivariate_normal(x0, P0, size=n, method="eigh")


def free_particles(sample_free: SampleFree | None, n: int, rng: np.random.Generator,
                   fallback: Callable[[int], Array]) -> Array:
    """``n`` free poses (n, 3) from ``sample_free``, or ``fallback(n)`` without one; a
    ValueError naming ``sample_free`` if it returns anything but finite (n, 3) poses."""
    if sample_free is None:
        return fallback(n)
    X = np.asarray(sample_free(n, rng), dtype=np.float64)
    if X.shape != (n, 3) or not np.all(np.isfinite(X)):
        raise ValueError(f"sample_free must return finite poses of shape ({n}, 3), got "
                         f"{X.shape}")
    return X
