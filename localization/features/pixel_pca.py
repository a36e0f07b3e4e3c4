"""PixelPCA: raw pixels in [0, 1] -> PCA, the classical appearance-based baseline, with an
optional per-image illumination normalisation (issue 14: the same place at dusk, at night or
over-exposed should give nearby features).

The "patches" normalisation is SeqSLAM's patch normalisation (Milford & Wyeth 2012, "SeqSLAM:
Visual route-based navigation for sunny summer days and stormy winter nights"): every patch of
``patch_size`` x ``patch_size`` pixels is standardized on its own, so a light that changes over
the picture (a low sun, a headlight, street lamps) cancels where a per-image gain cannot."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from localization._validation import check_choice, check_int, check_real
from localization.features._pca import fit_pca, pca_from_state, pca_project, pca_state
from localization.features.base import FeatureExtractor

__all__ = ["NORMALIZATIONS", "PixelPCA", "normalize_patches", "normalize_pixels", "smooth_images"]

#: the values of ``PixelPCA(normalize=...)``
NORMALIZATIONS = ("none", "standardize", "channels", "equalize", "patches")
_EPS = np.float32(1e-3)


def normalize_pixels(x: np.ndarray, how: str, channels: int) -> np.ndarray:
    """Per-image illumination normalisation of pixel rows.

    Parameters
    ----------
    x : (n, P) float32 — each row one image's pixels in [0, 1], channel fastest
        (P = pixels * channels).
    how : one of :data:`NORMALIZATIONS`
        "none": unchanged; "standardize": minus the image's mean, over its standard deviation
        (a global gain and offset cancel: exposure, dimmer light); "channels": the same per
        colour channel (also a colour cast cancels: dusk, seasons); "equalize": every channel
        replaced by the ranks of its values scaled to [0, 1] (histogram equalisation: any
        increasing change of brightness cancels), then standardized; "patches": as
        "standardize" (the patches themselves are normalized on the image by
        :func:`normalize_patches` before the pixels are flattened).
    channels : int — 3 for colour, 1 for grey.

    Returns
    -------
    (n, P) float32
    """
    if how == "none":
        return x
    n = len(x)
    if how in ("standardize", "patches"):
        z = x - x.mean(axis=1, keepdims=True)
        return z / (z.std(axis=1, keepdims=True) + _EPS)
    c = x.reshape(n, -1, channels)
    if how == "equalize":
        ranks = np.argsort(np.argsort(c, axis=1, kind="stable"), axis=1, kind="stable")
        c = ranks.astype(np.float32) / np.float32(max(c.shape[1] - 1, 1))
    z = c - c.mean(axis=1, keepdims=True)
    return (z / (z.std(axis=1, keepdims=True) + _EPS)).reshape(n, -1)


def normalize_patches(x: np.ndarray, size: int, floor: float) -> np.ndarray:
    """Standardize every ``size`` x ``size`` patch of every image and channel on its own.

    ``z = (x - mean_patch) / (std_patch + floor)``; the last row and column of patches are
    smaller when ``size`` does not divide H or W.

    Parameters
    ----------
    x : (n, H, W, C) float32 — pixels in [0, 1].
    size : int — patch side (px).
    floor : float — added to each patch's standard deviation: a flat patch stays near 0
        instead of blowing its quantisation noise up to unit variance.

    Returns
    -------
    (n, H, W, C) float32
    """
    rows, cols = np.arange(0, x.shape[1], size), np.arange(0, x.shape[2], size)

    def block_mean(v: np.ndarray) -> np.ndarray:
        sums = np.add.reduceat(np.add.reduceat(v, rows, axis=1), cols, axis=2)
        counts = np.outer(np.diff(rows, append=x.shape[1]), np.diff(cols, append=x.shape[2]))
        mean = sums / counts[None, :, :, None].astype(np.float32)
        return np.repeat(np.repeat(mean, size, axis=1), size, axis=2)[:, :x.shape[1], :x.shape[2]]

    z = x - block_mean(x)
    return z / (np.sqrt(block_mean(z * z)) + np.float32(floor))


def smooth_images(x: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur of standard deviation ``sigma`` (px) over the rows and columns of every
    image and channel (edges extended by their nearest pixel; truncated at 4 sigma).

    Parameters
    ----------
    x : (n, H, W, C) float32 — pixels.
    sigma : float >= 0 — 0 returns ``x``.

    Returns
    -------
    (n, H, W, C) float32
    """
    if sigma == 0:
        return x
    return ndimage.gaussian_filter(x, sigma=(0.0, sigma, sigma, 0.0), mode="nearest")


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
    normalize : {"none", "standardize", "channels", "equalize", "patches"}
        Per-image illumination normalisation of the (masked) pixels before the PCA
        (:func:`normalize_pixels`); "none" (default) keeps the raw pixels; "patches"
        standardizes every patch on its own (:func:`normalize_patches`, before the mask).
    patch_size : int
        Patch side (px) of ``normalize="patches"``.
    patch_floor : float
        Added to each patch's standard deviation (pixel values in [0, 1]) by
        ``normalize="patches"``.
    smooth : float
        Standard deviation (px) of a Gaussian blur of every image and channel before the
        normalisation (:func:`smooth_images`): sensor noise is averaged away before a flat
        patch's standardisation can blow it up; 0 (default) keeps the pixels.

    Attributes
    ----------
    pca_ : sklearn.decomposition.PCA
        Fitted on vectors of H * W * (1 or 3) pixels.
    image_shape_ : tuple of int
        (H, W) seen in fit.
    """

    name = "pixel_pca"

    def __init__(self, n_components: int = 64, grayscale: bool = False, whiten: bool = False,
                 random_state: int | None = 0, mask: Any = None,
                 normalize: str = "none", patch_size: int = 8,
                 patch_floor: float = 0.001, smooth: float = 0.0) -> None:
        self.n_components = n_components
        self.grayscale = grayscale
        self.whiten = whiten
        self.random_state = random_state
        self.mask = mask
        self.normalize = normalize
        self.patch_size = patch_size
        self.patch_floor = patch_floor
        self.smooth = smooth

    def _pixels(self, images: np.ndarray) -> np.ndarray:
        x = images.astype(np.float32) / np.float32(255.0)
        if self.grayscale:
            x = (x @ np.array([0.299, 0.587, 0.114], dtype=np.float32))[..., None]
        if self.smooth > 0:
            x = smooth_images(x, float(self.smooth))
        if self.normalize == "patches":
            x = normalize_patches(x, int(self.patch_size), float(self.patch_floor))
        if self.mask is not None:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != images.shape[1:3] or not mask.any():
                raise ValueError(f"mask must be a non-empty boolean (H, W) = "
                                 f"{images.shape[1:3]} array, got shape {mask.shape}")
            x = x[:, mask]  # (n, n_pixels, channels)
        return normalize_pixels(x.reshape(len(x), -1), self.normalize,
                                1 if self.grayscale else 3)

    def _fit(self, images: np.ndarray, y: Any = None) -> None:
        check_int(self.n_components, "n_components", low=1)
        check_choice(self.normalize, "normalize", NORMALIZATIONS)
        check_int(self.patch_size, "patch_size", low=1)
        check_real(self.patch_floor, "patch_floor", low=0.0, low_open=True)
        check_real(self.smooth, "smooth", low=0.0)
        self.pca_ = fit_pca(self._pixels(images), self.n_components, self.whiten,
                            self.random_state)

    def _transform(self, images: np.ndarray) -> np.ndarray:
        out = np.empty((len(images), self._n_out()), dtype=np.float64)
        for s in range(0, len(images), 1024):  # bounds the float64 temporaries of PCA
            out[s:s + 1024] = pca_project(self.pca_, self._pixels(images[s:s + 1024]))
        return out

    def _state_arrays(self) -> dict[str, np.ndarray]:
        return pca_state(self.pca_)

    def _load_arrays(self, state: dict[str, np.ndarray]) -> None:
        self.pca_ = pca_from_state(state, self.whiten)
        if self.pca_ is None:
            raise ValueError("PixelPCA state has no 'pca/components_'")

    def _n_out(self) -> int:
        return int(self.pca_.n_components_)
