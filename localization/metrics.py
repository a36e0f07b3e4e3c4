"""Error measures shared by the regressors, benchmarks and experiments.

Formulas (``theta_hat``, ``theta`` of shape (n, d); ``C`` the chosen columns):

* ``rmse``  = sqrt( (1/n) sum_i sum_{c in C} e_ic^2 ),  e = theta_hat - theta
  (an angle column in ``periodic`` uses the wrapped difference).
* ``rrmse`` = sqrt( sum_i sum_{c in C} (theta_hat_ic - theta_ic)^2
  / sum_i sum_{c in C} (theta_ic - mean_c(theta))^2 ),
  the relative RMSE used for the seed paper's Table II (the paper does not define
  it; this is the choice stated in docs/method.md §16.2). 0 is perfect;
  1 is what predicting the mean achieves. Periodic columns are excluded by default
  (their variance is not meaningful); for robot positions pass ``columns=(0, 1)``.
* ``angular_error`` = wrap(a - b) to (-pi, pi]; ``angular_rmse`` its RMS.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_array
from localization.geometry import Array, wrap_angle

__all__ = ["angular_error", "angular_rmse", "rmse", "rrmse", "wrap_angle"]


def _as_pair(a: ArrayLike, b: ArrayLike, names: tuple[str, str]) -> tuple[Array, Array]:
    """Validate two arrays of equal shape, 1-D (n,) promoted to (n, 1)."""
    a = check_array(a, names[0], finite=False)
    b = check_array(b, names[1], finite=False)
    if a.ndim == 1:
        a = a[:, None]
    if b.ndim == 1:
        b = b[:, None]
    if a.ndim != 2 or b.ndim != 2:
        raise ValueError(f"{names[0]} and {names[1]} must be 1-D or 2-D, got shapes "
                         f"{a.shape} and {b.shape}")
    if a.shape != b.shape:
        raise ValueError(f"shape mismatch: {names[0]} has shape {a.shape}, "
                         f"{names[1]} has shape {b.shape}")
    if a.shape[0] == 0:
        raise ValueError("empty input: need at least one sample")
    for name, x in zip(names, (a, b)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} contains NaN or inf")
    return a, b


def _columns(d: int, columns: Sequence[int] | None, periodic: Sequence[int]) -> list[int]:
    periodic = [int(p) % d for p in periodic]
    if columns is None:
        cols = [c for c in range(d) if c not in periodic]
        if not cols:
            raise ValueError("all columns are periodic; pass columns= explicitly")
        return cols
    cols = [int(c) for c in columns]
    if not cols:
        raise ValueError("columns is empty")
    bad = [c for c in cols if not -d <= c < d]
    if bad:
        raise ValueError(f"columns {bad} out of range for {d} columns")
    return [c % d for c in cols]


def angular_error(a: ArrayLike, b: ArrayLike) -> Array:
    """Signed angle difference ``a - b`` wrapped to (-pi, pi].

    Parameters
    ----------
    a, b : array_like of the same shape (any shape)
        Angles in radians.

    Returns
    -------
    ndarray of the same shape
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"shape mismatch: a has shape {a.shape}, b has shape {b.shape}")
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("angles contain NaN or inf")
    return wrap_angle(a - b)


def angular_rmse(a: ArrayLike, b: ArrayLike) -> float:
    """sqrt(mean(angular_error(a, b)**2)) in radians."""
    e = angular_error(a, b)
    if e.size == 0:
        raise ValueError("empty input: need at least one angle")
    return float(np.sqrt(np.mean(e**2)))


def _errors(theta_hat: Array, theta: Array, cols: list[int], periodic: Sequence[int]) -> Array:
    d = theta.shape[1]
    per = {int(p) % d for p in periodic}
    e = theta_hat[:, cols] - theta[:, cols]
    for j, c in enumerate(cols):
        if c in per:
            e[:, j] = wrap_angle(e[:, j])
    return e


def rmse(theta_hat: ArrayLike, theta: ArrayLike, columns: Sequence[int] | None = None,
         periodic: Sequence[int] = ()) -> float:
    """Root mean squared Euclidean error ``sqrt(mean_i |theta_hat_i - theta_i|^2)``.

    Parameters
    ----------
    theta_hat, theta : array_like of shape (n, d) or (n,)
        Estimates and ground truth.
    columns : sequence of int, optional
        Columns entering the norm; default all columns.
    periodic : sequence of int, default=()
        Angle columns: their differences are wrapped to (-pi, pi].

    Returns
    -------
    float
    """
    a, b = _as_pair(theta_hat, theta, ("theta_hat", "theta"))
    cols = _columns(a.shape[1], columns if columns is not None else range(a.shape[1]), ())
    e = _errors(a, b, cols, periodic)
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def rrmse(theta_hat: ArrayLike, theta: ArrayLike, columns: Sequence[int] | None = None,
          periodic: Sequence[int] = ()) -> float:
    """Relative RMSE ``sqrt(sum |theta_hat - theta|^2 / sum |theta - mean(theta)|^2)``.

    Sums run over samples and the chosen columns; the mean is per column over ``theta``.

    Parameters
    ----------
    theta_hat, theta : array_like of shape (n, d) or (n,)
        Estimates and ground truth.
    columns : sequence of int, optional
        Columns to use. Default: every column not listed in ``periodic``
        (for robot poses ``[x, y, yaw]`` pass ``columns=(0, 1)`` or ``periodic=(2,)``).
    periodic : sequence of int, default=()
        Angle columns; excluded from the default columns. If explicitly selected,
        their errors are wrapped (the denominator still uses the plain variance).

    Returns
    -------
    float
        0 for a perfect estimate, 1 for predicting the column means.

    Raises
    ------
    ValueError
        Shape mismatch, NaN/inf, or a target with zero variance in the chosen columns.
    """
    a, b = _as_pair(theta_hat, theta, ("theta_hat", "theta"))
    cols = _columns(a.shape[1], columns, periodic)
    e = _errors(a, b, cols, periodic)
    dev = b[:, cols] - b[:, cols].mean(axis=0)
    den = float(np.sum(dev**2))
    if den <= 0.0:
        raise ValueError("theta has zero variance in the chosen columns; RRMSE undefined")
    return float(np.sqrt(np.sum(e**2) / den))
