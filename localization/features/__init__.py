"""Visual features omega(X): uint8 image batches (n, H, W, 3) -> float64 features (n, m).

Three transformers with one scikit-learn interface (``fit`` / ``transform`` /
``fit_transform``, fitted attributes end in ``_``):

- :class:`PixelPCA`: raw pixels in [0, 1] -> PCA, the classical appearance-based baseline
  (numpy only);
- :class:`EfficientNetFeatures`: ImageNet EfficientNet-Lite0, global-pooled 1280-d features,
  optionally PCA-reduced (torch);
- :class:`SmallCNNFeatures`: a small self-supervised CNN trained in our simulator (torch).

:func:`make_features` builds one by name; every extractor saves to a flat
``dict[str, np.ndarray]`` with ``get_state`` (a JSON ``settings`` string plus arrays, so a
localizer stores it in one ``.npz`` with ``allow_pickle=False``) and loads with
:func:`features_from_state`. The torch-backed names load on first use, so importing this
package (or PixelPCA) does not import torch.
"""

from __future__ import annotations

import importlib
from typing import Any

import numpy as np

from localization._lazy import lazy_names
from localization.features.base import FeatureExtractor, check_images, read_settings
from localization.features.pixel_pca import PixelPCA

__all__ = [
    "FEATURE_NAMES",
    "EfficientNetFeatures",
    "FeatureExtractor",
    "PixelPCA",
    "SmallCNNFeatures",
    "check_images",
    "features_from_state",
    "make_features",
]

# name -> (module, class); the module is imported only when the extractor is asked for
_REGISTRY = {
    "pixel_pca": ("localization.features.pixel_pca", "PixelPCA"),
    "efficientnet": ("localization.features.imagenet", "EfficientNetFeatures"),
    "small_cnn": ("localization.features.small_cnn", "SmallCNNFeatures"),
}
FEATURE_NAMES = tuple(_REGISTRY)
_LAZY = {cls: mod.rpartition(".")[2] for mod, cls in _REGISTRY.values() if cls != "PixelPCA"}


def _extractor_class(name: str) -> type[FeatureExtractor]:
    module, cls = _REGISTRY[name]
    return getattr(importlib.import_module(module), cls)


def make_features(name: str, **kw: Any) -> FeatureExtractor:
    """Build a feature extractor by name: "pixel_pca", "efficientnet" or "small_cnn".

    Raises
    ------
    ValueError
        For an unknown name (the message lists the known ones).
    """
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ValueError(f"unknown features {name!r}; choose one of {', '.join(FEATURE_NAMES)}")
    return _extractor_class(name)(**kw)


def features_from_state(state: dict[str, np.ndarray]) -> FeatureExtractor:
    """Rebuild any fitted extractor from its :meth:`FeatureExtractor.get_state` dict."""
    state = dict(state)
    kind = read_settings(state).get("kind")
    if kind not in _REGISTRY:
        raise ValueError(f"unknown features kind {kind!r} in state; known: "
                         f"{', '.join(FEATURE_NAMES)}")
    return _extractor_class(kind).from_state(state)


__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals())
