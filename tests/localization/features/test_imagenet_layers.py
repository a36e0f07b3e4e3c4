"""EfficientNetFeatures beyond the default global pool: a middle layer, a spatial pyramid of
pools, whitening; the default stays the network's own global pool."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from localization.features import EfficientNetFeatures, features_from_state
from localization.features import efficientnet as enet
from localization.features.base import torch_threads
from localization.features.imagenet import pyramid_pool


@pytest.fixture(scope="module")
def images() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, size=(6, 64, 64, 3), dtype=np.uint8)


def test_default_is_the_networks_global_pool(images):
    ext = EfficientNetFeatures(input_size=64, num_threads=1, progress=False).fit(images)
    model = enet.load_efficientnet_lite0()
    with torch.inference_mode(), torch_threads(1):
        ref = model.features(enet.preprocess(torch.from_numpy(images), 64)).double().numpy()
    np.testing.assert_allclose(ext.transform(images), ref, rtol=0, atol=0)
    assert ext.n_features_out_ == 1280


def test_layers_channels_and_strides():
    model = enet.EfficientNetLite0().eval()
    x = torch.zeros(1, 3, 128, 128)
    with torch.inference_mode():
        for layer in ("block0", "block2", "block10", "block14", "block15", "head"):
            c, stride = enet.layer_channels(layer)
            assert model.layer_maps(x, layer).shape == (1, c, 128 // stride, 128 // stride)
        assert torch.equal(model.layer_maps(x, "head"), model.feature_maps(x))
    assert enet.layer_channels("block10") == (112, 16)
    assert enet.LAYERS[-1] == "head" and len(enet.LAYERS) == 17


def test_pyramid_pool_levels():
    maps = torch.arange(2 * 4 * 4, dtype=torch.float32).view(1, 2, 4, 4)
    out = pyramid_pool(maps, (1, 2))
    assert out.shape == (1, 2 * (1 + 4))
    np.testing.assert_allclose(out[0, :2], maps.mean(dim=(2, 3))[0])  # g = 1: global mean
    # g = 2: the top-left 2 x 2 cell of channel 0, scaled by 1/2
    np.testing.assert_allclose(out[0, 2], maps[0, 0, :2, :2].mean() / 2)


def test_middle_layer_grid_whitened_roundtrip(images, tmp_path):
    ext = EfficientNetFeatures(input_size=64, n_components=4, layer="block10", grid=(1, 2),
                               whiten=True, num_threads=1, progress=False)
    z = ext.fit_transform(images)
    assert z.shape == (6, 4) and ext.pooled_features(images).shape == (6, 112 * 5)
    np.testing.assert_allclose(z.std(axis=0, ddof=1), 1.0, rtol=1e-6)  # whitened
    np.savez(tmp_path / "e.npz", **ext.get_state())
    with np.load(tmp_path / "e.npz", allow_pickle=False) as state:
        loaded = features_from_state(state)
    assert loaded.layer == "block10" and tuple(loaded.grid) == (1, 2) and loaded.whiten
    np.testing.assert_array_equal(loaded.transform(images), ext.transform(images))


@pytest.mark.parametrize(("kw", "match"), [
    ({"layer": "block16"}, "layer must be one of"),
    ({"layer": "fc"}, "layer must be one of"),
    ({"grid": ()}, "grid must be"),
    ({"grid": (0, 2)}, "grid must be"),
    ({"grid": (2, 2)}, "grid must be"),
    ({"grid": "x"}, "grid must be"),
    ({"n_components": 0}, "n_components"),
])
def test_bad_settings_name_the_argument(images, kw, match):
    with pytest.raises(ValueError, match=match):
        EfficientNetFeatures(input_size=64, progress=False, **kw).fit(images)
