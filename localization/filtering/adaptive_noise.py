"""Innovation-adaptive measurement noise: R scaled up while the innovations say it is too small.

A noise model learned offline (one global R, or R(theta, w) from K-fold residuals) gives the
average error at a place. The GSE maps also err in runs: on a long straight a forward
camera's psi* can lag the robot by 0.4-1.8 m for 80 steps (docs/benchmarks.md §8, stop 42),
and the held-out residuals do not show it. An EKF that takes those frames at face value
ends a few centimetres off with standard deviations of 2-4 cm: over-confident (mean NEES 46 on
that drive). Innovation-based adaptive estimation (Mehra, "On the identification of
variances and adaptive Kalman filtering", IEEE TAC 1970; Mohamed and Schwarz, J. Geodesy
1999) reads the noise level off the filter's own innovations. Here, with the code's names::

    NIS0_k = y_k^T (H P H^T + R)^-1 y_k        (the gate's NIS, with the un-scaled R)
    m_k    = (1 - rate) m_{k-1} + rate min(NIS0_k, gate) / dim_z     (accepted updates)
    s_k    = clip(m_k, 1, max_scale),          R_k = s_k R

``m_0 = 1``. R only grows (``s >= 1``): the offline model stays the floor. The gate keeps the
un-scaled R (``gate_R``), so the scaling lowers the weight of the frames it lets through and
never lets through a frame the gate would reject. Gated frames do not count: they moved
nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization._validation import check_real, check_settings
from localization.filtering.ekf import noise_at
from localization.geometry import Array

__all__ = ["InnovationScale", "ScaledMeasurement", "innovation_scale"]


class ScaledMeasurement:
    """A measurement model whose R is ``scale`` times the wrapped model's; the gate's R and
    every other attribute (``h``, ``H``, ``residual``, ``observe``, ...) are the wrapped
    model's."""

    def __init__(self, model: Any, scale: float) -> None:
        self.model, self.scale = model, float(scale)

    def __getattr__(self, name: str) -> Any:
        if name == "model":  # not set yet (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.model, name)

    @property
    def R(self) -> Any:
        """``scale`` times the model's R (a callable ``R(x)`` stays one)."""
        R = self.model.R
        if callable(R):
            return lambda x: self.scale * np.asarray(R(x), dtype=np.float64)
        return self.scale * np.asarray(R, dtype=np.float64)

    def R_at(self, x: Array) -> Array:
        """``scale R(x)``."""
        return self.scale * noise_at(self.model, x)

    def gate_R(self, x: Array) -> Array:
        """The wrapped model's gate noise (its ``gate_R(x)``, else its R(x))."""
        gate_R = getattr(self.model, "gate_R", None)
        return np.asarray(gate_R(x), dtype=np.float64) if callable(gate_R) else \
            noise_at(self.model, x)


class InnovationScale:
    """The running scale ``s`` of R (see the module docstring).

    Parameters
    ----------
    rate : float in (0, 1]
        Weight of each accepted update's NIS in the running mean (about ``1 / rate`` steps).
    max_scale : float >= 1
        Upper bound of ``s``.

    Attributes
    ----------
    mean : float
        ``m_k``, the running mean of ``min(NIS0, gate) / dim_z``.
    """

    def __init__(self, rate: float = 0.1, max_scale: float = 10.0) -> None:
        self.rate = check_real(rate, "rate", low=0.0, high=1.0)
        if self.rate == 0.0:
            raise ValueError("rate must be in (0, 1], got 0")
        self.max_scale = check_real(max_scale, "max_scale", low=1.0)
        self.mean = 1.0

    @property
    def scale(self) -> float:
        """``s = clip(m, 1, max_scale)``."""
        return float(np.clip(self.mean, 1.0, self.max_scale))

    def reset(self) -> None:
        """Forget the innovations (a new start)."""
        self.mean = 1.0

    def wrap(self, model: Any) -> ScaledMeasurement:
        """``model`` with R scaled by today's ``s``."""
        return ScaledMeasurement(model, self.scale)

    def record(self, nis: float, dim_z: int, gate: float) -> None:
        """Fold an accepted update's gate NIS (with the un-scaled R) into the mean; a NaN
        NIS (no update) is ignored."""
        if np.isfinite(nis):
            self.mean += self.rate * (min(float(nis), gate) / dim_z - self.mean)


def innovation_scale(option: bool | dict[str, Any] | InnovationScale) -> InnovationScale | None:
    """The :class:`InnovationScale` an ``adaptive_noise`` option asks for (None: off;
    :func:`~localization._validation.check_settings`)."""
    return check_settings(option, "adaptive_noise", InnovationScale)
