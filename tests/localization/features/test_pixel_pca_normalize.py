"""PixelPCA's illumination normalisation (issue 14): what each mode cancels, its state."""

from __future__ import annotations

import numpy as np
import pytest

from localization.features.pixel_pca import (
    NORMALIZATIONS,
    PixelPCA,
    normalize_patches,
    normalize_pixels,
    smooth_images,
)


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


def light_gradient(images, left=0.9, right=0.3):
    """A light that falls off across the picture (a low sun, a headlight): a gain per column."""
    gain = np.linspace(left, right, images.shape[2])[None, None, :, None]
    return np.clip(np.round(images * gain), 0, 255).astype(np.uint8)


def test_patches_cancel_a_light_that_changes_over_the_picture(images):
    ref = PixelPCA(n_components=8, normalize="patches", patch_size=4).fit(images)
    whole = PixelPCA(n_components=8, normalize="channels").fit(images)
    changed = light_gradient(images)
    err = {name: np.linalg.norm(m.transform(images) - m.transform(changed), axis=1).mean()
           / np.linalg.norm(m.transform(images), axis=1).mean()
           for name, m in [("patches", ref), ("channels", whole)]}
    assert err["patches"] < 0.1
    assert err["channels"] > 2 * err["patches"]


def test_normalize_patches_moments_and_ragged_edges():
    x = np.random.default_rng(2).uniform(0, 1, (3, 10, 13, 3)).astype(np.float32)
    z = normalize_patches(x, 4, 1e-6)
    assert z.shape == x.shape and z.dtype == np.float32
    for r, c in [(slice(0, 4), slice(0, 4)), (slice(8, 10), slice(12, 13)),
                 (slice(4, 8), slice(12, 13))]:  # whole, corner and edge patches
        block = z[:, r, c]
        assert np.allclose(block.mean(axis=(1, 2)), 0, atol=1e-4)
        assert np.allclose(block.std(axis=(1, 2)), 1, atol=1e-3)
    flat = normalize_patches(np.full((1, 8, 8, 1), 0.5, np.float32), 4, 1e-3)
    assert np.all(flat == 0)  # a flat patch stays 0: the floor, not 0 / 0


def test_patches_settings_are_saved_and_masks_apply_after_them(images):
    mask = np.zeros(images.shape[1:3], bool)
    mask[:6] = True
    fitted = PixelPCA(n_components=4, normalize="patches", patch_size=3, patch_floor=0.01,
                      grayscale=True, mask=mask).fit(images)
    again = PixelPCA.from_state(fitted.get_state())
    assert (again.patch_size, again.patch_floor) == (3, 0.01)
    assert np.array_equal(again.transform(images), fitted.transform(images))


@pytest.mark.parametrize("params, exc", [({"patch_size": 0}, ValueError),
                                         ({"patch_size": 2.5}, TypeError),
                                         ({"patch_floor": 0.0}, ValueError),
                                         ({"patch_floor": float("nan")}, ValueError),
                                         ({"patch_floor": "small"}, TypeError),
                                         ({"smooth": -0.5}, ValueError),
                                         ({"smooth": float("inf")}, ValueError)])
def test_bad_patch_settings_are_named(images, params, exc):
    with pytest.raises(exc, match=next(iter(params))):
        PixelPCA(n_components=4, normalize="patches", **params).fit(images)


def test_smoothing_averages_sensor_noise_before_the_patches_blow_it_up():
    # a scene of smooth gradients (flat 4 x 4 patches at the floor) under sensor noise of 0.05:
    # the blur brings the noisy image's features back towards the clean image's
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:16, 0:16] / 16.0
    phases = rng.uniform(0, 2 * np.pi, (30, 1, 1, 3))
    clean = 0.5 + 0.3 * np.sin(2 * np.pi * (xx + yy)[None, :, :, None] + phases)
    noisy = np.clip(clean + rng.normal(0.0, 0.05, clean.shape), 0, 1)
    to_u8 = lambda x: np.round(255 * x).astype(np.uint8)

    def feature_gap(smooth):
        pca = PixelPCA(n_components=8, normalize="patches", patch_size=4,
                       smooth=smooth).fit(to_u8(clean))
        gap = pca.transform(to_u8(noisy)) - pca.transform(to_u8(clean))
        return np.linalg.norm(gap, axis=1).mean()

    assert feature_gap(1.0) < 0.5 * feature_gap(0.0)


def test_smooth_zero_keeps_the_pixels_and_the_setting_is_saved(images):
    x = images.astype(np.float32) / 255
    assert smooth_images(x, 0.0) is x
    blurred = smooth_images(x, 1.0)
    assert blurred.shape == x.shape and blurred.dtype == np.float32
    assert blurred.std() < x.std()  # averages neighbours, per channel
    assert np.allclose(blurred.mean(axis=(1, 2)), x.mean(axis=(1, 2)), atol=0.02)
    fitted = PixelPCA(n_components=4, normalize="patches", smooth=0.8).fit(images)
    again = PixelPCA.from_state(fitted.get_state())
    assert again.smooth == 0.8
    assert np.array_equal(again.transform(images), fitted.transform(images))
