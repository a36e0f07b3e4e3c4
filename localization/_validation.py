"""Argument checks shared by the public API: one definition of each (numpy only).

Every check names the argument and the problem in its message and raises the natural type:
``TypeError`` for a value of the wrong kind (a float seed, a complex or string array, a
non-dict ``options``), ``ValueError`` for a value of the right kind that is not allowed
(negative, NaN, wrong shape, unknown key or choice), ``FileNotFoundError`` for a missing
file. Valid values come back converted (``int``, ``float``, float64 arrays) and otherwise
unchanged, so checking never changes what valid input computes.

This module sits in the lowest layer (next to :mod:`localization.geometry`): :mod:`envs`,
every layer of :mod:`localization` and :mod:`agents` may use it.
"""

from __future__ import annotations

import copy
import numbers
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "check_array",
    "check_bool",
    "check_choice",
    "check_existing_file",
    "check_images",
    "check_int",
    "check_options",
    "check_real",
    "check_seed",
    "check_settings",
]

Shape = tuple[int | None, ...]
T = TypeVar("T")


def _kind(value: object) -> str:
    return type(value).__name__


def check_bool(value: object, name: str) -> bool:
    """``value`` as a bool; ``TypeError`` unless it is a bool (or numpy bool)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {value!r} ({_kind(value)})")
    return bool(value)


def check_int(value: object, name: str, *, low: int | None = None, high: int | None = None) -> int:
    """``value`` as an int in ``[low, high]`` (a bound of None is open).

    Raises
    ------
    TypeError
        If it is not an integer (``int`` or a numpy integer; bools and floats are refused).
    ValueError
        If it is outside ``[low, high]``.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {value!r} ({_kind(value)})")
    v = int(value)
    if (low is not None and v < low) or (high is not None and v > high):
        raise ValueError(f"{name} must be {_range(low, high)}, got {v}")
    return v


def check_seed(value: object, name: str = "seed", *, optional: bool = False) -> int | None:
    """A random seed: a non-negative integer (or None when ``optional``)."""
    if value is None and optional:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        none = " or None" if optional else ""
        raise TypeError(f"{name} must be a non-negative integer{none}, got {value!r} ({_kind(value)})")
    if int(value) < 0:
        raise ValueError(f"{name} must be a non-negative integer, got {int(value)}")
    return int(value)


def check_real(value: object, name: str, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a finite float in the interval ``[low, high]`` (``low_open``: ``(low, ...``).

    Raises
    ------
    TypeError
        If it is not a real number (bools, complex numbers and strings are refused).
    ValueError
        If it is NaN, infinite or outside the interval.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {value!r} ({_kind(value)})")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    if (low is not None and (v < low or (low_open and v == low))) or \
            (high is not None and (v > high or (high_open and v == high))):
        raise ValueError(f"{name} must be {_interval(low, high, low_open, high_open)}, got {v}")
    return v


def check_choice(value: object, name: str, choices: Collection[Any]) -> Any:
    """``value`` if it is one of ``choices`` (the message lists them)."""
    try:
        ok = value in choices
    except TypeError:  # unhashable
        ok = False
    if not ok:
        raise ValueError(f"unknown {name} {value!r}; choose one of {list(choices)}")
    return value


def check_options(options: object, name: str, allowed: Iterable[str]) -> dict[str, Any]:
    """A dict of options (``None`` -> ``{}``) whose keys are all in ``allowed``.

    Raises
    ------
    TypeError
        If ``options`` is not a mapping.
    ValueError
        If it has a key not in ``allowed`` (the message lists the allowed keys).
    """
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"{name} must be a dict or None, got {_kind(options)}")
    allowed = sorted(allowed)
    unknown = sorted(str(k) for k in options if k not in allowed)
    if unknown:
        raise ValueError(f"unknown {name} key(s) {unknown}; allowed keys: {allowed}")
    return dict(options)


def check_settings(option: object, name: str, cls: type[T]) -> T | None:
    """The settings object a bool-or-settings option asks for: False -> None, True ->
    ``cls()``, a dict -> ``cls(**option)``, a ``cls`` instance -> a deep copy of it (e.g.
    ``BeliefFilter(adaptive_noise=...)``). The copy matters for the stateful ones
    (``InnovationScale``'s running mean, ``DivergenceMonitor``'s windows): one instance given
    to two filters, or to a wrapper that makes one filter per env, would otherwise be shared
    and each filter would read the other's innovations, as scikit-learn clones an estimator
    given as a parameter.

    Raises
    ------
    TypeError
        If ``option`` is of another kind, or the dict has a key ``cls`` does not take (the
        message names ``name``).
    """
    if isinstance(option, cls):
        return copy.deepcopy(option)
    if isinstance(option, (bool, np.bool_)):
        return cls() if option else None
    if isinstance(option, Mapping):
        try:
            return cls(**option)
        except TypeError as err:
            raise TypeError(f"{name}: {err}") from None
    raise TypeError(f"{name} must be a bool, a dict of {cls.__name__} settings or a "
                    f"{cls.__name__}, got {_kind(option)}")


def check_array(value: object, name: str, *, shape: Shape | None = None, ndim: int | None = None,
                finite: bool = True, what: str = "") -> NDArray[np.float64]:
    """``value`` as a float64 array of the given shape (None: any size on that axis).

    Parameters
    ----------
    value : array-like of real numbers.
    name : the argument's name, used in messages.
    shape : expected shape, e.g. ``(3,)`` or ``(None, 3)``; ``ndim`` alone checks only the rank.
    finite : refuse NaN and inf.
    what : a description appended to the shape in messages, e.g. ``"[x, y, yaw]"``.

    Raises
    ------
    TypeError
        If the values are not real numbers (complex, bool, strings, objects, None).
    ValueError
        If the array is ragged, has the wrong shape, or holds NaN/inf when ``finite``.
    """
    a = _as_real_array(value, name)
    expect = f" {what}" if what else ""
    if shape is not None:
        if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
            raise ValueError(f"{name} must have shape {_shape(shape)}{expect}, got shape {a.shape}")
    elif ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name} must be a {ndim}-D array{expect}, got shape {a.shape}")
    if finite and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return a


def check_images(images: object, name: str = "images", *, single: bool = False) -> NDArray[Any]:
    """A batch of images ``(n, H, W, C)`` (or one ``(H, W, C)`` when ``single``), n >= 1,
    of real numbers without NaN; returned as an array of its own dtype (uint8 stays uint8).

    Raises
    ------
    TypeError
        If the pixels are not real numbers (complex, bool, strings, objects).
    ValueError
        If the array is ragged, has the wrong rank, is empty or holds NaN/inf.
    """
    a = np.asarray(images) if isinstance(images, np.ndarray) else _as_array(images, name)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real pixel values, got dtype {a.dtype}")
    rank = 3 if single else 4
    layout = "(H, W, C)" if single else "(n, H, W, C)"
    if a.ndim != rank:
        raise ValueError(f"{name} must have shape {layout}, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name} must not be empty, got shape {a.shape}")
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return a


def check_existing_file(path: object, name: str = "path") -> Path:
    """``path`` as a Path to an existing file (``TypeError`` if it is not path-like)."""
    if not isinstance(path, (str, Path)) and not hasattr(path, "__fspath__"):
        raise TypeError(f"{name} must be a path (str or os.PathLike), got {_kind(path)}")
    p = Path(path)  # type: ignore[arg-type]
    if not p.is_file():
        raise FileNotFoundError(f"{name}: no such file {p}")
    return p


# ---------------------------------------------------------------------- helpers
def _as_array(value: object, name: str) -> NDArray[Any]:
    try:
        return np.asarray(value)
    except ValueError:  # ragged nested sequences
        raise ValueError(f"{name} must be a rectangular array of numbers, got a ragged sequence"
                         ) from None


def _as_real_array(value: object, name: str) -> NDArray[np.float64]:
    a = _as_array(value, name)
    if a.dtype.kind == "c":
        raise TypeError(f"{name} must be real, got complex values (dtype {a.dtype})")
    if a.dtype.kind in "iuf":
        return a.astype(np.float64, copy=False)
    if a.dtype.kind == "O":
        items = a.ravel().tolist()
        if all(isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) for v in items):
            return a.astype(np.float64)
    raise TypeError(f"{name} must hold real numbers, got dtype {a.dtype}: {_short(value)}")


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _shape(shape: Shape) -> str:
    dims = ["n" if s is None else str(s) for s in shape]
    return f"({dims[0]},)" if len(dims) == 1 else "(" + ", ".join(dims) + ")"


def _range(low: int | None, high: int | None) -> str:
    if high is None and low in (0, 1):
        return "a positive integer" if low == 1 else "a non-negative integer"
    if low is not None and high is not None:
        return f"an integer in [{low}, {high}]"
    return f"an integer >= {low}" if low is not None else f"an integer <= {high}"


def _interval(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    if low is not None and high is not None:
        return f"in {'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"
    if low is not None:
        return f"{'>' if low_open else '>='} {low}"
    return f"{'<' if high_open else '<='} {high}"
