"""Augmented MCL's likelihood averages: when to inject particles (Thrun et al.).

Probabilistic Robotics, table 8.3: a short- and a long-term average of the measurement
likelihood; while the short one falls below the long one, a share of the particles is
replaced by fresh guesses. With the names of the code::

    w_slow += alpha_slow (w_avg - w_slow),  w_fast += alpha_fast (w_avg - w_fast)
    p_inject = min(max_injection, max(0, 1 - w_fast / (injection_ratio w_slow)))

(both averages start at the first ``w_avg``). ``injection_ratio = 1`` is Thrun's rule;
the particle belief's default 0.7 leaves the ordinary ups and downs of the likelihood alone
(w_fast / w_slow wanders in 0.8-1.2 while tracking). The belief leaves the particles it
has just injected out of ``w_avg``, so that they do not lower it and call for more.
"""

from __future__ import annotations

import numpy as np

from localization._validation import check_real

__all__ = ["LikelihoodAverages"]


class LikelihoodAverages:
    """Short- and long-term averages of the likelihood (see the module docstring).

    Parameters
    ----------
    alpha_slow, alpha_fast : float
        Averaging rates, ``0 < alpha_slow < alpha_fast <= 1``.
    injection_ratio : float in (0, 1]
    max_injection : float in [0, 1]
        Cap of the injected share per step (0: never inject).

    Attributes
    ----------
    w_slow, w_fast : float
        The averages (NaN before the first :meth:`update`).
    """

    def __init__(self, alpha_slow: float = 0.01, alpha_fast: float = 0.2,
                 injection_ratio: float = 0.7, max_injection: float = 0.5) -> None:
        if not (0.0 < alpha_slow < alpha_fast <= 1.0):
            raise ValueError(f"need 0 < alpha_slow < alpha_fast <= 1, got {alpha_slow}, "
                             f"{alpha_fast}")
        self.alpha_slow, self.alpha_fast = float(alpha_slow), float(alpha_fast)
        self.injection_ratio = check_real(injection_ratio, "injection_ratio", low=0.0,
                                          high=1.0, low_open=True)
        self.max_injection = check_real(max_injection, "max_injection", low=0.0, high=1.0)
        self.reset()

    def reset(self) -> None:
        """Forget the averages."""
        self.w_slow = self.w_fast = np.nan

    def update(self, w_avg: float) -> None:
        """Move both averages towards this step's likelihood ``w_avg``."""
        self.w_slow = w_avg if np.isnan(self.w_slow) else \
            self.w_slow + self.alpha_slow * (w_avg - self.w_slow)
        self.w_fast = w_avg if np.isnan(self.w_fast) else \
            self.w_fast + self.alpha_fast * (w_avg - self.w_fast)

    @property
    def injection_probability(self) -> float:
        """Share of the particles to replace by fresh guesses this step."""
        return min(self.max_injection,
                   max(0.0, 1.0 - self.w_fast / (self.injection_ratio * self.w_slow)))
