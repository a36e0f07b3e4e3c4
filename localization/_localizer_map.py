"""The map a localizer knows: the city it was fitted on and a fingerprint of its images.

A localizer learns one city's appearance; in another city its images look like nothing it
has seen, or worse, like somewhere else, and the belief goes confidently wrong (issue 12:
a localizer fitted on city 0 ran in city 1 with 57 % of its measurements accepted, 7.6 m
off). So :meth:`AppearanceLocalizer.fit` records

- ``city_``: what the env says about its city (:func:`city_info`: the scene seed, the
  layout parameters, the street centrelines and a digest of the buildings), or None when
  the images come from elsewhere (recorded data, an older file);
- ``fingerprint_``: a SHA-256 of a fixed subsample of the training images (:func:`images_fingerprint`),
  which names the training set even without a city;

and :meth:`MapMixin.check_city` refuses another city unless told to. :func:`city_info` is
duck-typed (it reads ``env.unwrapped.city``; nothing here imports :mod:`envs`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from typing import Any

import numpy as np

__all__ = ["MapMixin", "OtherCityError", "city_info", "describe_city", "images_fingerprint"]

#: images hashed by :func:`images_fingerprint` (evenly spaced over the training set)
FINGERPRINT_IMAGES = 64
#: city dataclass fields renamed in :func:`city_info`
_RENAME = {"seed": "scene_seed", "size": "city_size"}
_SCALARS = (bool, int, float, str)


class OtherCityError(ValueError):
    """The localizer was fitted on another city than the env's (see :meth:`MapMixin.check_city`)."""


def city_info(env: Any) -> dict[str, Any]:
    """What an env says about its city, as a JSON-friendly dict.

    Parameters
    ----------
    env : gymnasium.Env or City
        An ``AppearanceNav-v0`` env (wrapped or not: ``env.unwrapped.city`` is read) or its
        :class:`envs.scene.City`.

    Returns
    -------
    dict
        ``scene_seed``, ``city_size``, ``street_width`` and every other scalar field of the
        city (a look-alike option, ...), ``streets`` (the street centrelines, m, rounded to
        1e-6) and ``layout`` (a SHA-256 digest of the streets and buildings: centres, sizes
        and colours), which tells two cities apart even when their parameters agree.

    Raises
    ------
    TypeError
        If ``env`` has no city.
    """
    city = getattr(getattr(env, "unwrapped", env), "city", None)
    if city is None and hasattr(env, "street_centers"):
        city = env
    if city is None or not hasattr(city, "street_centers"):
        raise TypeError(f"env must be an AppearanceNav env (with env.unwrapped.city) or its City, "
                        f"got {type(env).__name__}")
    names = ([f.name for f in dataclasses.fields(city)] if dataclasses.is_dataclass(city)
             else ["seed", "size", "street_width"])
    info: dict[str, Any] = {}
    for name in names:
        value = getattr(city, name, None)
        value = value.item() if isinstance(value, np.generic) else value
        if isinstance(value, _SCALARS):
            info[_RENAME.get(name, name)] = value
    streets = np.round(np.asarray(city.street_centers, dtype=np.float64), 6)
    info["streets"] = [float(s) for s in streets]
    info["layout"] = _layout_digest(streets, getattr(city, "buildings", []))
    return info


def _layout_digest(streets: np.ndarray, buildings: list[Any]) -> str:
    """SHA-256 (first 16 hex digits) of the street centrelines and the buildings' boxes
    and colours, rounded to 1e-6."""
    h = hashlib.sha256(np.ascontiguousarray(streets).tobytes())
    for b in buildings:
        parts = [getattr(b, k, ()) for k in ("center", "half_size", "rgb")]
        row = np.round(np.concatenate([np.ravel(np.asarray(p, dtype=np.float64))
                                       for p in parts]), 6)
        h.update(np.ascontiguousarray(row).tobytes())
    return h.hexdigest()[:16]


def images_fingerprint(images: np.ndarray, n: int = FINGERPRINT_IMAGES) -> str:
    """SHA-256 hex digest of the image stack's shape and ``n`` evenly spaced images' bytes.

    Cheap (64 images whatever the training set's size) and deterministic: the same training
    images give the same fingerprint, other images (another city, another camera) another.

    Parameters
    ----------
    images : ndarray (N, H, W, 3) uint8
    """
    images = np.asarray(images)
    h = hashlib.sha256(repr((images.shape, str(images.dtype))).encode())
    if len(images):
        idx = np.unique(np.linspace(0, len(images) - 1, min(n, len(images))).round().astype(int))
        for i in idx:
            h.update(np.ascontiguousarray(images[i]).tobytes())
    return h.hexdigest()


def check_city_info(city: object, name: str = "city") -> dict[str, Any] | None:
    """Validate a city description (a dict of str keys, JSON-friendly values) or None."""
    if city is None:
        return None
    if not isinstance(city, dict):
        raise TypeError(f"{name} must be a dict from city_info(env) or None, got "
                        f"{type(city).__name__}")
    out = {}
    for k, v in city.items():
        if not isinstance(k, str):
            raise TypeError(f"{name} keys must be str, got {k!r}")
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, (list, tuple)):
            v = [float(x) for x in v]
        elif v is not None and not isinstance(v, _SCALARS):
            raise TypeError(f"{name}[{k!r}] must be a number, str, bool or list of numbers, "
                            f"got {type(v).__name__}")
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{name}[{k!r}] must be finite, got {v}")
        out[k] = v
    return out


def describe_city(city: dict[str, Any] | None) -> str:
    """A short description of a city (``"city scene_seed=0 (20 m, streets 2 m, layout ...)"``)."""
    if city is None:
        return "an unknown city"
    extras = [f"{k}={v}" for k, v in city.items()
              if k not in ("scene_seed", "city_size", "street_width", "streets", "layout")]
    size = [f"{city['city_size']:g} m"] if "city_size" in city else []
    width = [f"streets {city['street_width']:g} m"] if "street_width" in city else []
    layout = [f"layout {city['layout']}"] if "layout" in city else []
    return (f"city scene_seed={city.get('scene_seed', '?')} "
            f"({', '.join(size + width + extras + layout)})")


def city_differences(fitted: dict[str, Any], actual: dict[str, Any]) -> list[str]:
    """``"key: fitted != actual"`` for every key both describe with different values."""
    return [f"{k}: {fitted[k]!r} != {actual[k]!r}" for k in fitted
            if k in actual and fitted[k] != actual[k]]


class MapMixin:
    """``check_city`` of the localizer (uses its ``city_`` and ``fingerprint_``)."""

    def check_city(self, city: dict[str, Any] | None, *, allow_other_city: bool = False) -> None:
        """Refuse to run in another city than the one the localizer was fitted on.

        Parameters
        ----------
        city : dict or None
            The env's city, :func:`city_info` (``city_info(env)``); None: unknown.
        allow_other_city : bool
            Run anyway (e.g. to measure how a localizer does elsewhere).

        Raises
        ------
        OtherCityError (a ValueError)
            If both cities are known and differ (scene seed, layout parameters, streets or
            buildings) and ``allow_other_city`` is False. A localizer whose city is unknown
            (fitted without ``city=``, e.g. on recorded data, or loaded from a format-2 file)
            is not checked.
        """
        self._check_fitted()
        city = check_city_info(city)
        if not isinstance(allow_other_city, (bool, np.bool_)):
            raise TypeError(f"allow_other_city must be a bool, got "
                            f"{type(allow_other_city).__name__}")
        fitted = getattr(self, "city_", None)
        if fitted is None or city is None or allow_other_city:
            return
        diffs = city_differences(fitted, city)
        if diffs:
            fp = getattr(self, "fingerprint_", None) or "unknown"
            raise OtherCityError(
                f"the localizer (training images {fp[:12]}) was fitted on "
                f"{describe_city(fitted)} but the env is {describe_city(city)} "
                f"({'; '.join(diffs)}). It has only learned how its own city looks: fit one "
                f"for this city (fit_city_localizer(env)), or pass allow_other_city=True "
                f"(command line: --allow-other-city) to run it here anyway.")

    def map_info(self) -> dict[str, Any]:
        """The city (``city_``, None if unknown) and training images (``fingerprint_``)."""
        self._check_fitted()
        return {"city": getattr(self, "city_", None),
                "fingerprint": getattr(self, "fingerprint_", None),
                "camera": self.camera_, "image_size": tuple(self.image_size_)}

