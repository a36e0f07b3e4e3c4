"""The feature-extractor factory of the paper's experiment: a name -> a fresh extractor."""

from __future__ import annotations

from typing import Any

from localization.workflows.camera_masks import ground_mask

__all__ = ["EXTRACTORS", "IMAGENET_GRID", "IMAGENET_LAYER", "make_extractor"]

#: names :func:`make_extractor` knows ("efficientnet_global": the network's own global pool of
#: its final maps, the features of the first runs, which alias on the route)
EXTRACTORS = ("pixel_pca", "pixel_pca_masked", "efficientnet", "efficientnet_global",
              "small_cnn")
#: The ImageNet features of the experiment: EfficientNet-Lite0's block 10 (112 maps at 1/16 of
#: the input), average-pooled over 1x1, 2x2 and 3x3 grids (a spatial pyramid, 1568 numbers),
#: then PCA. See :class:`~localization.features.imagenet.EfficientNetFeatures` and
#: docs/results.md for why (the head's global pool aliases look-alike places).
IMAGENET_LAYER, IMAGENET_GRID = "block10", (1, 2, 3)


def make_extractor(name: str, camera: str, mode: str, n_components: int, image_size: int,
                   ground_range: float = 3.0, num_threads: int = 2,
                   smooth: float = 0.0) -> Any:
    """A fresh, unfitted feature extractor.

    Parameters
    ----------
    name : one of :data:`EXTRACTORS`: PixelPCA, PixelPCA with the near ground masked
        (:func:`~localization.workflows.camera_masks.ground_mask`), EfficientNet-Lite0
        (ImageNet; :data:`IMAGENET_LAYER` pooled over :data:`IMAGENET_GRID`, or the global
        pool of the head), or the SmallCNN trained on other cities for ``camera`` and
        ``mode``.
    camera, mode : the images' camera and data set mode (the mask and the SmallCNN weights).
    n_components : PCA dimension of the features.
    image_size : side of the square images (the mask; the ImageNet network's input size:
        the images are not resized).
    ground_range : the mask hides ground closer than this (m).
    num_threads : torch threads of the CNNs.
    smooth : the PixelPCAs' Gaussian blur (px) before the PCA (``PixelPCA(smooth=...)``).
    """
    from localization.features import EfficientNetFeatures, PixelPCA
    from localization.features.small_cnn import SmallCNNFeatures
    from localization.features.weights import small_cnn_weights

    if name == "pixel_pca":
        return PixelPCA(n_components, smooth=smooth)
    if name == "pixel_pca_masked":
        return PixelPCA(n_components, mask=ground_mask(camera, image_size, ground_range),
                        smooth=smooth)
    if name == "efficientnet":
        return EfficientNetFeatures(input_size=image_size, n_components=n_components,
                                    layer=IMAGENET_LAYER, grid=IMAGENET_GRID,
                                    num_threads=num_threads)
    if name == "efficientnet_global":
        return EfficientNetFeatures(input_size=image_size, n_components=n_components,
                                    num_threads=num_threads)
    if name == "small_cnn":
        return SmallCNNFeatures(n_components=n_components,
                                weights=str(small_cnn_weights(camera, mode)),
                                num_threads=num_threads)
    raise ValueError(f"unknown feature extractor {name!r}; choose one of {EXTRACTORS}")
