"""PixelPCA's illumination normalisation (issue 14): what each mode cancels, its state."""

from __future__ import annotations

import numpy as np
import pytest

from localization.features.pixel_pca import NORMALIZATIONS, PixelPCA, normalize_pixels


@pytest.fixture(scope="module")
def images():
    rng = np.random.default_rng(0)
    base = rng.uniform(40, 200, (40, 12, 16, 3))
    return base.astype(np.uint8)


def dim(images, gain=(1.0, 1.0, 1.0), gamma=1.0):
    x = (images / 255.0) ** gamma * np.asarray(gain)
    return np.clip(np.round(255 * x), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("how, change, tol", [
    ("standardize", {"gain": (0.5, 0.5, 0.5)}, 0.02),  # a dimmer light
    ("channels", {"gain": (0.9, 0.6, 0.4)}, 0.03),     # a warm colour cast (dusk)
    ("equalize", {"gamma": 1.8, "gain": (0.7, 0.7, 0.7)}, 0.05),  # any brighter-to-darker map
])
def test_each_mode_cancels_its_change_and_none_does_not(images, how, change, tol):
    ref = PixelPCA(n_components=8, normalize=how).fit(images)
    raw = PixelPCA(n_components=8).fit(images)
    a, b = ref.transform(images), ref.transform(dim(images, **change))
    scale = np.linalg.norm(a, axis=1).mean()
    assert np.linalg.norm(a - b, axis=1).mean() < tol * scale
    c, d = raw.transform(images), raw.transform(dim(images, **change))
    assert np.linalg.norm(c - d, axis=1).mean() > 5 * tol * np.linalg.norm(c, axis=1).mean()


def test_normalize_pixels_shapes_and_moments():
    x = np.random.default_rng(1).uniform(0, 1, (5, 30)).astype(np.float32)
    assert normalize_pixels(x, "none", 3) is x
    for how in NORMALIZATIONS[1:]:
        z = normalize_pixels(x, how, 3)
        assert z.shape == x.shape and z.dtype == np.float32
        assert np.allclose(z.mean(axis=1), 0, atol=1e-5)
    z = normalize_pixels(x, "channels", 3).reshape(5, 10, 3)
    assert np.allclose(z.std(axis=1), 1, atol=1e-2)


def test_normalize_is_saved_in_the_state(images):
    fitted = PixelPCA(n_components=4, normalize="equalize").fit(images)
    again = PixelPCA.from_state(fitted.get_state())
    assert again.normalize == "equalize"
    assert np.array_equal(again.transform(images), fitted.transform(images))


@pytest.mark.parametrize("bad, exc", [("gamma", ValueError), ("", ValueError),
                                      (None, ValueError), (1, ValueError)])
def test_unknown_normalize_is_named(images, bad, exc):
    with pytest.raises(exc, match="normalize"):
        PixelPCA(n_components=4, normalize=bad).fit(images)
