"""The base of the feature extractors: :class:`FeatureExtractor` (uint8 images (n, H, W, 3)
-> float64 features (n, m), saved as a flat dict of arrays) and the helpers the extractors
share. The extractors themselves and their registry are in :mod:`localization.features`.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.exceptions import NotFittedError
from tqdm.auto import tqdm

__all__ = ["FeatureExtractor", "batched", "check_images", "read_settings", "torch_threads"]



def check_images(images: Any, name: str = "images") -> np.ndarray:
    """Validate an image batch: uint8 array of shape (n, H, W, 3) with n >= 1.

    Raises
    ------
    ValueError
        Naming the wrong ndim, channel count, dtype or an empty batch.
    """
    arr = np.asarray(images)
    if arr.ndim != 4:
        raise ValueError(f"{name} must have shape (n, H, W, 3), got ndim={arr.ndim} "
                         f"(shape {arr.shape}); wrap a single image as images[None]")
    if arr.shape[-1] != 3:
        raise ValueError(f"{name} must have 3 RGB channels in the last axis, got shape {arr.shape}")
    if arr.dtype != np.uint8:
        raise ValueError(f"{name} must have dtype uint8 (values 0..255), got dtype {arr.dtype}")
    if arr.shape[0] == 0 or arr.shape[1] == 0 or arr.shape[2] == 0:
        raise ValueError(f"{name} is empty: shape {arr.shape}")
    return arr


@contextlib.contextmanager
def torch_threads(num_threads: int | None) -> Iterator[None]:
    """Temporarily set ``torch.set_num_threads`` (no-op for None); restores the old value."""
    import torch  # only the torch-backed extractors call this

    old = torch.get_num_threads()
    change = num_threads is not None and int(num_threads) != old
    if change:
        torch.set_num_threads(int(num_threads))
    try:
        yield
    finally:
        if change:
            torch.set_num_threads(old)


def batched(n: int, batch_size: int, progress: bool, desc: str) -> Iterator[slice]:
    """Slices over ``range(n)``; a tqdm bar unless ``progress`` is False or n <= batch_size."""
    starts = range(0, n, batch_size)
    bar = tqdm(starts, desc=desc, unit="batch", disable=(not progress) or n <= batch_size,
               leave=False)
    for s in bar:
        yield slice(s, min(s + batch_size, n))


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"setting of type {type(obj).__name__} is not JSON-serialisable: {obj!r}")


def _json_array(settings: dict[str, Any]) -> np.ndarray:
    return np.array(json.dumps(settings, sort_keys=True, default=_json_default))


def read_settings(state: dict[str, np.ndarray]) -> dict[str, Any]:
    """Decode the JSON ``settings`` entry of a state (0-d str array or uint8 bytes)."""
    if "settings" not in state:
        raise ValueError("state has no 'settings' entry; was it made by get_state()?")
    raw = np.asarray(state["settings"])
    text = raw.tobytes().decode() if raw.dtype == np.uint8 else str(raw[()])
    return json.loads(text)


class FeatureExtractor(TransformerMixin, BaseEstimator):
    """Base class: input validation, fitted check, image-size check, state (de)serialisation.

    Subclasses implement ``_fit(images, y)``, ``_transform(images) -> (n, m) float64``,
    ``_state_arrays()`` and ``_load_arrays(state)``; ``name`` is the ``make_features`` key.
    """

    name: ClassVar[str] = ""

    def fit(self, images: np.ndarray, y: Any = None) -> FeatureExtractor:
        """Fit on uint8 images (n, H, W, 3); remembers (H, W) in ``image_shape_``.

        ``y`` (poses (n, 3)) is ignored except by ``SmallCNNFeatures`` trained with
        ``objective="pose_contrastive"``.
        """
        images = check_images(images)
        self._fit(images, y)
        self.image_shape_ = (int(images.shape[1]), int(images.shape[2]))
        return self

    def fit_transform(self, images: np.ndarray, y: Any = None) -> np.ndarray:
        """``fit(images).transform(images)``, reusing network outputs computed during fit."""
        images = check_images(images)
        out = self._fit(images, y)
        self.image_shape_ = (int(images.shape[1]), int(images.shape[2]))
        return self.transform(images) if out is None else self._checked(out)

    def transform(self, images: np.ndarray) -> np.ndarray:
        """Features of uint8 images (n, H, W, 3) -> float64 array (n, n_features_out_)."""
        return self._checked(self._transform(self._checked_images(images)))

    def _checked_images(self, images: np.ndarray) -> np.ndarray:
        self._check_fitted()
        images = check_images(images)
        if tuple(images.shape[1:3]) != tuple(self.image_shape_):
            raise ValueError(f"images: image size {tuple(images.shape[1:3])} differs from the size "
                             f"{tuple(self.image_shape_)} this {type(self).__name__} was fitted on")
        return images

    # -- a first stage several extractors may share ----------------------------------------
    def stage_key(self) -> str | None:
        """Identity of a fixed first stage (a trained network) that other fitted extractors
        may share: extractors with equal keys give equal :meth:`embed` outputs, so a
        localizer of several maps runs it once per image. None (the default): no such
        stage, :meth:`embed` returns the images."""
        return None

    def embed(self, images: np.ndarray) -> np.ndarray:
        """The first stage of :meth:`transform` on uint8 images (n, H, W, 3): an array (n, ...)
        with ``transform(images) == head(embed(images))``."""
        return self._embed(self._checked_images(images))

    def head(self, embedded: np.ndarray) -> np.ndarray:
        """The rest of :meth:`transform`: features (n, n_features_out_) of :meth:`embed`'s
        output."""
        self._check_fitted()
        return self._checked(self._head(embedded))

    def _checked(self, out: np.ndarray) -> np.ndarray:
        out = np.asarray(out, dtype=np.float64)
        if not np.all(np.isfinite(out)):
            raise ValueError(f"{type(self).__name__} produced non-finite features")
        return out

    def _check_fitted(self) -> None:
        if not hasattr(self, "image_shape_"):
            raise NotFittedError(f"This {type(self).__name__} instance is not fitted yet; "
                                 "call fit(images) first")

    def get_state(self) -> dict[str, np.ndarray]:
        """Flat dict of arrays: ``settings`` (0-d JSON str: kind, hyperparameters, image shape)
        plus the fitted arrays. Saves with ``np.savez(path, **state)`` and ``allow_pickle=False``.
        """
        self._check_fitted()
        settings = {"kind": self.name, "params": self.get_params(deep=False),
                    "image_shape": list(self.image_shape_)}
        return {"settings": _json_array(settings), **self._state_arrays()}

    @classmethod
    def from_state(cls, state: dict[str, np.ndarray]) -> FeatureExtractor:
        """Rebuild a fitted extractor from :meth:`get_state` (also accepts an ``NpzFile``)."""
        state = dict(state)
        settings = read_settings(state)
        if settings.get("kind") != cls.name:
            raise ValueError(f"state is for features {settings.get('kind')!r}, not {cls.name!r}")
        obj = cls(**settings["params"])
        obj._load_arrays(state)
        obj.image_shape_ = tuple(int(v) for v in settings["image_shape"])
        return obj

    @property
    def n_features_out_(self) -> int:
        """Output dimension m of ``transform``."""
        self._check_fitted()
        return self._n_out()

    # -- subclass hooks ------------------------------------------------------------------------
    def _fit(self, images: np.ndarray, y: Any = None) -> np.ndarray | None:
        """Fit; may return the transform of ``images`` if it was computed on the way."""
        raise NotImplementedError

    def _transform(self, images: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {}

    def _load_arrays(self, state: dict[str, np.ndarray]) -> None:
        pass

    def _n_out(self) -> int:
        raise NotImplementedError

    def _embed(self, images: np.ndarray) -> np.ndarray:
        return images

    def _head(self, embedded: np.ndarray) -> np.ndarray:
        return self._transform(embedded)
