"""Feature settings of the street-wide localizers of the coverage, city60 and robustness
benchmarks.

``"small_cnn"`` is the packaged SmallCNN of the camera trained pose-contrastively on random
views of cities 100-119 (``small_cnn_<camera>_random.pt``,
:func:`~localization.features.weights.small_cnn_weights`), on the whole image, PCA to
``n_components``; ``"pixel_pca"`` is the localizer's default, PixelPCA on its upper image rows.
Chosen on tuning cities 11 and 12 (64 x 64 perspective, 10000 street-lane images, 1000
held-out ones; psi* median error / share beyond 1 m): PixelPCA(64) 0.167 m / 2.3 % and
0.152 m / 2.9 %, the SmallCNN 0.115 m / 0.5 % and 0.116 m / 0.4 % (the SmallCNN trained on
route images: 0.080 m / 3.5 % on city 11, more look-alikes); on the coverage data of tuning
cities 12 and 13 see :mod:`.coverage`.
"""

from __future__ import annotations

from typing import Any

__all__ = ["FEATURES", "features_label", "localizer_features"]

#: feature extractors the benchmarks accept (the first is their default)
FEATURES = ("small_cnn", "pixel_pca")


def localizer_features(features: str, camera: str, n_components: int) -> dict[str, Any]:
    """The :class:`~localization.localizer.AppearanceLocalizer` keyword arguments of
    ``features`` on ``camera``."""
    if features == "pixel_pca":
        return {"features_params": {"n_components": n_components}}
    if features != "small_cnn":
        raise ValueError(f"features must be one of {', '.join(FEATURES)}, got {features!r}")
    from localization.features.weights import small_cnn_weights

    return {"features": "small_cnn", "rows": (0.0, 1.0),
            "features_params": {"n_components": n_components, "progress": False,
                                "weights": str(small_cnn_weights(camera, "random"))}}


def features_label(features: str, n_components: int) -> str:
    """The feature extractor in a report's words."""
    if features == "pixel_pca":
        return f"PixelPCA({n_components})"
    return f"SmallCNN (random views of other cities; PCA {n_components}, whole image)"
