"""KLD-sampling: as many particles as the belief's spread needs (Fox 2003, AMCL's rule).

A tracking belief sits in a handful of pose bins and needs a few hundred particles; a lost
one spread over the city needs thousands. Fox ("Adapting the sample size in particle filters
through KLD-sampling", IJRR 22(12), 2003) bounds, with probability ``1 - delta``, the
Kullback-Leibler distance between the sample-based and the true posterior by ``epsilon``
when the sample size is (``k`` occupied bins, ``z`` the standard normal's upper ``1 - delta``
quantile)::

    n = (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3

ROS / nav2 AMCL (``pf_resample_limit``) use the same bound with bins of 0.5 m x 0.5 m x 10
degrees, ``epsilon = 0.05`` (``pf_err``), clamped to ``[min_particles, max_particles]``
(defaults 500 and 2000); so do these defaults. (nav2 passes ``pf_z = 0.99`` itself as ``z``;
here ``z`` is the quantile of ``confidence``, as in Fox's paper: 2.33 at 0.99.)
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import norm

from localization._validation import check_int, check_real
from localization.filtering._modes import cells
from localization.geometry import Array

__all__ = ["KLD_BIN", "KLDSampling", "kld_sample_size", "occupied_bins"]

#: AMCL's histogram bins: 0.5 m in x and y, 10 degrees of heading
KLD_BIN = (0.5, float(np.deg2rad(10.0)))


def kld_sample_size(k: int, epsilon: float = 0.05, confidence: float = 0.99) -> int:
    """Fox's bound: particles that keep the KL distance below ``epsilon`` with probability
    ``confidence`` when the belief occupies ``k`` bins (``k <= 1``: 1)."""
    if k <= 1:
        return 1
    z = _quantile(confidence)
    b = 2.0 / (9.0 * (k - 1))
    return int(np.ceil((k - 1) / (2.0 * epsilon) * (1.0 - b + np.sqrt(b) * z) ** 3))


@lru_cache(maxsize=8)
def _quantile(confidence: float) -> float:
    """The standard normal's ``confidence`` quantile (scipy's ppf costs ~0.1 ms a call)."""
    return float(norm.ppf(confidence))


def occupied_bins(X: ArrayLike, size: float = KLD_BIN[0], heading_size: float = KLD_BIN[1]
                  ) -> int:
    """Number of pose bins (``size`` m x ``size`` m x ``heading_size`` rad) the poses
    ``X`` (n, 3) occupy."""
    X = np.asarray(X, dtype=np.float64)
    return int(cells(X, size, size / heading_size).max()) + 1 if len(X) else 0


class KLDSampling:
    """The particle count after a resampling: Fox's bound on the resampled set's bins,
    clamped to ``[min_particles, max_particles]``.

    Parameters
    ----------
    min_particles, max_particles : int
        The clamp (AMCL's ``min_particles`` / ``max_particles``).
    epsilon : float in (0, 1)
        Bound on the KL distance (AMCL's ``pf_err``).
    confidence : float in (0, 1)
        Probability of the bound (AMCL's ``pf_z``).
    """

    def __init__(self, min_particles: int, max_particles: int, epsilon: float = 0.05,
                 confidence: float = 0.99) -> None:
        self.max_particles = check_int(max_particles, "max_particles", low=1)
        self.min_particles = check_int(min_particles, "min_particles", low=1,
                                       high=self.max_particles)
        self.epsilon = check_real(epsilon, "kld_epsilon", low=0.0, high=1.0, low_open=True,
                                  high_open=True)
        self.confidence = check_real(confidence, "kld_confidence", low=0.0, high=1.0,
                                     low_open=True, high_open=True)

    def size(self, X: ArrayLike) -> int:
        """Particles (int) the poses ``X`` (n, 3) call for."""
        n = kld_sample_size(occupied_bins(X), self.epsilon, self.confidence)
        return int(np.clip(n, self.min_particles, self.max_particles))

    def adapt(self, X: Array, fresh: Array, rng: np.random.Generator) -> tuple[Array, Array]:
        """Resampled particles ``X`` (N, 3) with their injected flags ``fresh`` (N,), thinned
        (evenly spaced from a random offset, which keeps a systematic resampling's strata) or
        grown (copies of random ones; the next prediction's noise sets them apart) to
        :meth:`size`."""
        n, N = self.size(X), len(X)
        if n < N:
            keep = (rng.random() + np.arange(n)) * (N / n)
            idx = np.minimum(keep.astype(np.intp), N - 1)
        elif n > N:
            idx = np.concatenate([np.arange(N), rng.integers(N, size=n - N)])
        else:
            return X, fresh
        return X[idx], fresh[idx]
