"""The image side of :class:`~localization.localizer.AppearanceLocalizer` (a mixin): images
checked against the fitted size, cropped to the localizer's rows, and their features
w = omega(X), with the extractor's first stage (its network) exposed so that several maps on
one network run it once (:func:`localization._district_maps.transform_maps`).

The host class provides ``rows``, ``image_size_``, ``features_`` and ``_check_fitted``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from localization._validation import check_images
from localization.geometry import Array

__all__ = ["ImageFeaturesMixin"]


class ImageFeaturesMixin:
    """Image validation, the rows crop and the features of the localizer."""

    rows: tuple[float, float]
    image_size_: tuple[int, int]
    features_: Any
    _check_fitted: Any

    def _row_slice(self, height: int) -> slice:
        a, b = (float(r) for r in self.rows)
        if not 0.0 <= a < b <= 1.0:
            raise ValueError(f"rows must be fractions 0 <= start < stop <= 1, got {self.rows}")
        start = round(a * height)
        return slice(start, max(round(b * height), start + 1))

    def _crop(self, images: NDArray[np.uint8]) -> NDArray[np.uint8]:
        return np.ascontiguousarray(images[:, self._row_slice(images.shape[1])])

    def check_images(self, images: ArrayLike) -> NDArray[np.uint8]:
        """Validate an image (H, W, 3) or batch (n, H, W, 3) against the fitted image size."""
        self._check_fitted()
        images = check_images(images, "images", single=np.ndim(images) == 3)
        if images.ndim == 3:
            images = images[None]
        if images.ndim != 4 or images.shape[-1] != 3:
            raise ValueError(f"images must have shape (n, H, W, 3), got {images.shape}")
        if tuple(images.shape[1:3]) != tuple(self.image_size_):
            raise ValueError(f"the localizer was fitted on {tuple(self.image_size_)} images, "
                             f"got {tuple(images.shape[1:3])}")
        if images.dtype != np.uint8:
            raise ValueError(f"images must be uint8, got {images.dtype}")
        return images

    def transform(self, images: ArrayLike) -> Array:
        """Features w = omega(X) of images, shape (n, m)."""
        crop = self._crop(self.check_images(images))
        return self.features_.transform(crop)

    def stage_key(self) -> tuple[Any, ...] | None:
        """Identity of the feature extractor's first stage on this localizer's image rows
        (:meth:`FeatureExtractor.stage_key`): localizers with equal keys give equal
        :meth:`embed` outputs. None: the extractor has no stage to share."""
        self._check_fitted()
        key = self.features_.stage_key()
        if key is None:
            return None
        return key, tuple(float(r) for r in self.rows), tuple(self.image_size_)

    def embed(self, images: ArrayLike) -> Array:
        """The first stage of :meth:`transform`: ``transform(X) == head(embed(X))``."""
        return self.features_.embed(self._crop(self.check_images(images)))

    def head(self, embedded: ArrayLike) -> Array:
        """The rest of :meth:`transform`: features w (n, m) of :meth:`embed`'s output."""
        return self.features_.head(np.asarray(embedded))
