"""The feature-extractor factory of the paper's experiment: a name -> a fresh extractor."""

from __future__ import annotations

from typing import Any

from localization.workflows.camera_masks import ground_mask

__all__ = ["EXTRACTORS", "make_extractor"]

#: names :func:`make_extractor` knows
EXTRACTORS = ("pixel_pca", "pixel_pca_masked", "efficientnet", "small_cnn")


def make_extractor(name: str, camera: str, mode: str, n_components: int, image_size: int,
                   ground_range: float = 3.0, num_threads: int = 2) -> Any:
    """A fresh, unfitted feature extractor.

    Parameters
    ----------
    name : one of :data:`EXTRACTORS`: PixelPCA, PixelPCA with the near ground masked
        (:func:`~localization.workflows.camera_masks.ground_mask`), EfficientNet-Lite0
        (ImageNet) or the SmallCNN trained on other cities for ``camera`` and ``mode``.
    camera, mode : the images' camera and data set mode (the mask and the SmallCNN weights).
    n_components : PCA dimension of the features.
    image_size : side of the square images (the mask).
    ground_range : the mask hides ground closer than this (m).
    num_threads : torch threads of the CNNs.
    """
    from localization.features import EfficientNetFeatures, PixelPCA
    from localization.features.small_cnn import SmallCNNFeatures
    from localization.features.weights import small_cnn_weights

    if name == "pixel_pca":
        return PixelPCA(n_components)
    if name == "pixel_pca_masked":
        return PixelPCA(n_components, mask=ground_mask(camera, image_size, ground_range))
    if name == "efficientnet":
        return EfficientNetFeatures(n_components=n_components, num_threads=num_threads)
    if name == "small_cnn":
        return SmallCNNFeatures(n_components=n_components,
                                weights=str(small_cnn_weights(camera, mode)),
                                num_threads=num_threads)
    raise ValueError(f"unknown feature extractor {name!r}; choose one of {EXTRACTORS}")
