"""Input validation of the regressors and the embedding: scikit-learn's own checks.

One path validates every array that reaches GSE, its regressor and the baselines:
:func:`check_2d` (a bare array) and :func:`validate_X` (an estimator's input, which also
records or checks ``n_features_in_`` / ``feature_names_in_``) run
``sklearn.utils.validation.check_array`` / ``validate_data``, so sparse, complex, object,
empty and wrongly sized inputs get scikit-learn's messages; every message is prefixed
with the name of the argument. Non-finite values are reported with the row that holds
them, and 1-D input with the reshape that fixes it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from scipy import sparse
from sklearn.utils.validation import check_array, validate_data

from localization.geometry import Array

__all__ = ["check_2d", "validate_X", "validate_y"]


@contextmanager
def _named(name: str) -> Iterator[None]:
    """Re-raise scikit-learn's ValueError / TypeError with the argument's name in front."""
    try:
        yield
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        if "features, but" in msg:  # sklearn's n_features_in_ mismatch
            msg += " (the number of columns must be the one seen in fit)"
        raise type(exc)(f"{name}: {msg}") from None


def _reject_1d(X: object, name: str) -> None:
    if not sparse.issparse(X) and hasattr(X, "__len__") and np.ndim(X) == 1:
        raise ValueError(f"{name} must be 2-D (n_samples, n_features), got a 1-D array of "
                         f"shape {np.shape(X)}. Reshape your data with {name}.reshape(-1, 1) "
                         f"for one feature or {name}.reshape(1, -1) for one sample")


def _check_finite(X: Array, name: str) -> Array:
    bad = ~np.isfinite(X).reshape(len(X), -1).all(axis=1)
    if bad.any():
        raise ValueError(f"{name} contains NaN or inf in {bad.sum()} row(s), first row "
                         f"{int(np.flatnonzero(bad)[0])}")
    return X


def _validated(run: Callable[[], Any], X: object, name: str) -> Array:
    _reject_1d(X, name)
    with _named(name):
        out = run()
    return _check_finite(out, name)


def check_2d(X: object, name: str, n_cols: int | None = None) -> Array:
    """A finite float64, C-contiguous 2-D array (n, n_cols); clear ValueError otherwise.

    For arrays that are not an estimator's ``X`` (poses, representations, cuts).
    """
    if _ready(X, None):
        X = _check_finite(X, name)  # type: ignore[arg-type]
    else:
        X = _validated(lambda: check_array(X, dtype=np.float64, order="C",
                                           ensure_all_finite=False, input_name=name), X, name)
    if n_cols is not None and X.shape[1] != n_cols:
        raise ValueError(f"{name} has {X.shape[1]} columns, expected {n_cols} (as in fit)")
    return X


def _ready(X: object, n_cols: int | None, min_rows: int = 1) -> bool:
    """``X`` is already what validation returns: a float64, C-ordered 2-D ndarray with
    ``n_cols`` columns (any if None) and at least ``min_rows`` rows (a filter's one image or
    pose per step: scikit-learn's checks cost more than the query)."""
    return (type(X) is np.ndarray and X.dtype == np.float64 and X.ndim == 2
            and X.flags.c_contiguous and X.shape[0] >= min_rows
            and (n_cols is None or X.shape[1] == n_cols))


def validate_X(estimator: Any, X: object, name: str = "X", *, reset: bool,
               ensure_min_samples: int = 1) -> Array:
    """An estimator's 2-D input through ``validate_data`` (float64, C order, finite).

    ``reset=True`` (fit) records ``n_features_in_``; ``reset=False`` checks it (an input
    that is already a float64 C-ordered array of that width, to an estimator fitted without
    feature names, is only checked to be finite).
    """
    if (not reset and not hasattr(estimator, "feature_names_in_")
            and _ready(X, getattr(estimator, "n_features_in_", -1), ensure_min_samples)):
        return _check_finite(X, name)  # type: ignore[arg-type]
    return _validated(lambda: validate_data(estimator, X, reset=reset, dtype=np.float64,
                                            order="C", ensure_all_finite=False,
                                            ensure_min_samples=ensure_min_samples), X, name)


def validate_y(estimator: Any, y: object, n_samples: int, name: str = "y",
               x_name: str = "X") -> tuple[Array, bool]:
    """A regression target of shape (n,) or (n, n_outputs) as a finite float64 2-D array.

    Returns the (n, n_outputs) array and whether ``y`` was 1-D (predictions then are too).
    """
    if y is None:
        raise ValueError(f"{type(estimator).__name__} requires y to be passed, but the target "
                         f"y is None (argument {name})")
    with _named(name):
        Y = check_array(y, dtype=np.float64, ensure_2d=False, allow_nd=True,
                        ensure_all_finite=False, input_name=name)
    if Y.ndim not in (1, 2):
        raise ValueError(f"{name} must be 1-D (n_samples,) or 2-D (n_samples, n_outputs), got "
                         f"shape {Y.shape}")
    if len(Y) != n_samples:
        raise ValueError(f"{x_name} and {name} have inconsistent numbers of samples: {x_name} has "
                         f"{n_samples} rows, {name} has {len(Y)}")
    is_1d = Y.ndim == 1
    Y = np.ascontiguousarray(Y[:, None] if is_1d else Y)
    if Y.shape[1] == 0:
        raise ValueError(f"{name} has no columns (shape {Y.shape})")
    return _check_finite(Y, name), is_1d
