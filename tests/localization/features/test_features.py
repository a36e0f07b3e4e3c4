"""Tests of the visual features omega(X): PixelPCA, EfficientNetFeatures, SmallCNNFeatures."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
import torch
from sklearn.datasets import load_sample_image
from sklearn.exceptions import NotFittedError

from localization.features import (
    EfficientNetFeatures,
    PixelPCA,
    check_images,
    features_from_state,
    make_features,
)
from localization.features import efficientnet as enet
from localization.features.small_cnn import (
    SmallCNNFeatures,
    load_small_cnn,
    pose_neighbors,
    save_small_cnn,
    train_small_cnn,
)

SIZE = 64


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread() -> Iterator[None]:
    old = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(old)


def panoramas(n_pano: int, seed: int, width: int = 4 * SIZE) -> np.ndarray:
    """Smooth random colour panoramas with blocky "facades": (n_pano, SIZE, width, 3) in [0, 1]."""
    rng = np.random.default_rng(seed)
    xs = (np.arange(width) / width)[None, None, :, None]
    freqs = rng.integers(1, 6, size=(n_pano, 6, 1, 1))
    phase = rng.uniform(0, 2 * np.pi, size=(n_pano, 6, 1, 3))
    colour = 0.5 + 0.1 * np.sin(2 * np.pi * freqs * xs + phase).sum(1)  # (n, width, 3)
    facades = 0.3 * (rng.uniform(size=(n_pano, width // 16, 3)).repeat(16, axis=1) - 0.5)
    shade = 0.7 + 0.3 * np.sin(np.linspace(0, np.pi, SIZE))[None, :, None, None]
    return np.clip(shade * (colour + facades)[:, None], 0, 1)


def crops(pano: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """SIZE x SIZE crops of one panorama (SIZE, width, 3) at horizontal offsets -> uint8."""
    return np.stack([(255 * pano[:, o:o + SIZE]).astype(np.uint8) for o in offsets])


@pytest.fixture(scope="module")
def images() -> np.ndarray:
    """48 crops: 8 panoramas x 6 random offsets, uint8 (48, 64, 64, 3)."""
    rng = np.random.default_rng(0)
    return np.concatenate([crops(p, rng.integers(0, 3 * SIZE, 6)) for p in panoramas(8, 0)])


@pytest.fixture(scope="module")
def cnn_weights(images: np.ndarray, tmp_path_factory: pytest.TempPathFactory) -> str:
    model = train_small_cnn(images, epochs=3, seed=0, batch_size=16, embedding_dim=32, width=16,
                            progress=False)
    path = tmp_path_factory.mktemp("cnn") / "small_cnn.pt"
    save_small_cnn(model, path)
    return str(path)


def extractors(weights: str) -> list:
    return [PixelPCA(16), PixelPCA(8, grayscale=True, whiten=True),
            EfficientNetFeatures(n_components=None, progress=False),
            EfficientNetFeatures(n_components=12, progress=False),
            SmallCNNFeatures(16, weights=weights, progress=False)]


def test_shapes_dtypes_determinism_and_state_roundtrip(images, cnn_weights, tmp_path):
    dims = [16, 8, 1280, 12, 16]
    images = images[::2]
    for ext, m in zip(extractors(cnn_weights), dims):
        z = ext.fit(images).transform(images)
        assert z.shape == (len(images), m) and z.dtype == np.float64, type(ext)
        assert ext.n_features_out_ == m and np.all(np.isfinite(z))
        np.testing.assert_array_equal(z, ext.transform(images))  # deterministic
        np.testing.assert_array_equal(z, type(ext)(**ext.get_params()).fit_transform(images))
        path = tmp_path / f"{ext.name}.npz"
        np.savez(path, **ext.get_state())
        with np.load(path, allow_pickle=False) as state:
            loaded = features_from_state(state)
        assert type(loaded) is type(ext) and loaded.get_params() == ext.get_params()
        np.testing.assert_array_equal(loaded.transform(images), z)


def test_make_features_factory():
    assert isinstance(make_features("pixel_pca", n_components=3), PixelPCA)
    assert isinstance(make_features("efficientnet", input_size=64), EfficientNetFeatures)
    assert isinstance(make_features("small_cnn", epochs=1), SmallCNNFeatures)
    with pytest.raises(ValueError, match="pixel_pca, efficientnet, small_cnn"):
        make_features("sift")


@pytest.mark.parametrize("ext", [PixelPCA(4), EfficientNetFeatures(progress=False),
                                 SmallCNNFeatures(4, epochs=1, progress=False)])
def test_bad_inputs(ext, images):
    with pytest.raises(NotFittedError):
        ext.transform(images)
    with pytest.raises(ValueError, match="ndim=3"):
        ext.fit(images[0])
    with pytest.raises(ValueError, match="3 RGB channels"):
        ext.fit(images[..., :2])
    with pytest.raises(ValueError, match="dtype uint8"):
        ext.fit(images.astype(np.float32))
    with pytest.raises(ValueError, match="empty"):
        ext.fit(images[:0])
    ext.fit(images[:16])
    with pytest.raises(ValueError, match=r"image size \(32, 32\) differs"):
        ext.transform(images[:2, :32, :32])
    with pytest.raises(ValueError, match="state is for features"):
        type(ext).from_state({"settings": np.array('{"kind": "other"}')})


def test_state_settings_accept_paths_and_numpy_scalars(images, cnn_weights):
    from pathlib import Path

    ext = SmallCNNFeatures(np.int64(4), weights=Path(cnn_weights), progress=False).fit(images)
    loaded = features_from_state(ext.get_state())
    assert loaded.n_components == 4 and loaded.weights == cnn_weights
    np.testing.assert_array_equal(loaded.transform(images), ext.transform(images))


def test_check_images_accepts_lists_of_uint8():
    arr = check_images([np.zeros((4, 5, 3), np.uint8)])
    assert arr.shape == (1, 4, 5, 3)


def test_efficientnet_weights_load_strictly_and_are_imagenet():
    model = enet.load_efficientnet_lite0()  # strict=True inside
    state = torch.load(enet.weights_path(), weights_only=True)
    assert set(model.state_dict()) == set(state)
    assert sum(p.numel() for p in model.parameters()) == 4_652_008
    # A real photograph shipped with scikit-learn: a daisy (ImageNet class 985).
    img = load_sample_image("flower.jpg")
    h, w, _ = img.shape
    s = min(h, w)
    img = np.ascontiguousarray(img[(h - s) // 2:(h - s) // 2 + s, (w - s) // 2:(w - s) // 2 + s])
    x = torch.from_numpy(img[None])
    with torch.inference_mode():
        prob = torch.softmax(model(enet.preprocess(x, 224)), dim=1)[0]
    assert int(prob.argmax()) == 985 and float(prob[985]) > 0.15
    # The TF Lite normalisation (x - 127) / 128 fits the weights better than torchvision's.
    xt = x.permute(0, 3, 1, 2).float()
    xt = torch.nn.functional.interpolate(xt, size=(224, 224), mode="bilinear", antialias=True)
    mean = torch.tensor([123.675, 116.28, 103.53]).view(1, 3, 1, 1)
    std = torch.tensor([58.395, 57.12, 57.375]).view(1, 3, 1, 1)
    with torch.inference_mode():
        prob_tv = torch.softmax(model((xt - mean) / std), dim=1)[0]
    assert float(prob[985]) > float(prob_tv[985])


def test_efficientnet_same_padding_output_size():
    model = enet.EfficientNetLite0().eval()
    with torch.inference_mode():
        assert model.feature_maps(torch.zeros(1, 3, 96, 96)).shape == (1, 1280, 3, 3)
        assert model.feature_maps(torch.zeros(1, 3, 65, 64)).shape == (1, 1280, 3, 2)


def shift_distance(feats: list[np.ndarray], k: int) -> float:
    """Mean feature distance between views k pixels apart, over sequences of shifted views."""
    return float(np.mean([np.linalg.norm(f[k:] - f[:-k], axis=1).mean() for f in feats]))


def test_features_change_smoothly_with_shifts(cnn_weights):
    """Shifting a view by 1 px moves features much less than switching to an unrelated view,
    and the feature distance grows with the shift."""
    panos = panoramas(4, 1)
    offsets = np.arange(20, 36)
    for ext in extractors(cnn_weights)[:3] + extractors(cnn_weights)[4:]:
        seqs = [crops(p, offsets) for p in panos]
        ext.fit(np.concatenate(seqs))
        feats = [ext.transform(seq) for seq in seqs]
        far = np.mean([np.linalg.norm(feats[i] - feats[j], axis=1).mean()
                       for i in range(4) for j in range(i + 1, 4)])
        near = [shift_distance(feats, k) for k in (1, 4, 12)]
        assert near[0] < 0.7 * far, (type(ext).__name__, near, far)
        assert near[0] < near[1] < near[2], (type(ext).__name__, near)  # grows with the shift


def test_small_cnn_training_decreases_loss_and_is_deterministic(images, tmp_path):
    a = train_small_cnn(images, epochs=3, seed=3, batch_size=16, progress=False)
    assert len(a.loss_history) == 3 and a.loss_history[-1] < a.loss_history[0]
    b = train_small_cnn(images, epochs=3, seed=3, batch_size=16, progress=False)
    for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(va, vb), k
    c = train_small_cnn(images, epochs=2, seed=3, batch_size=16, objective="contrastive",
                        embedding_dim=32, width=8, progress=False)
    assert len(c.loss_history) == 2 and np.all(np.isfinite(c.loss_history))
    save_small_cnn(c, tmp_path / "c.pt")
    d = load_small_cnn(tmp_path / "c.pt")
    x = torch.randn(2, 3, SIZE, SIZE)
    with torch.inference_mode():
        assert torch.equal(c.embed(x), d.embed(x))
    n_params = sum(p.numel() for p in a.encoder.parameters())
    assert 100_000 <= n_params <= 500_000


def test_small_cnn_fit_trains_without_weights(images):
    ext = SmallCNNFeatures(n_components=None, embedding_dim=16, width=8, epochs=1,
                           batch_size=16, progress=False).fit(images)
    assert len(ext.model_.loss_history) == 1
    assert ext.transform(images[:3]).shape == (3, 16)


def test_pose_neighbors_stay_in_group_and_are_nearest():
    x = np.arange(10.0)
    poses = np.c_[np.r_[x, x], np.zeros(20), np.zeros(20)]
    groups = np.repeat([0, 1], 10)
    nb = pose_neighbors(poses, groups, k=2)
    assert nb.shape == (20, 2)
    assert np.all(groups[nb] == groups[:, None]) and np.all(nb != np.arange(20)[:, None])
    assert set(nb[5]) == {4, 6} and set(nb[15]) == {14, 16} and set(nb[0]) == {1, 2}
    turned = poses.copy()
    turned[1, 2] = np.pi  # same place, opposite heading: no longer a near neighbour of 0
    assert 1 not in pose_neighbors(turned, groups, k=2)[0]
    with pytest.raises(ValueError, match="need more than n_neighbors"):
        pose_neighbors(poses[:3], None, k=3)


def test_pose_contrastive_training(images):
    poses = np.c_[np.arange(len(images)) % 6, np.zeros(len(images)), np.zeros(len(images))]
    groups = np.arange(len(images)) // 6  # one "city" per panorama, 6 views each
    model = train_small_cnn(images, epochs=2, seed=0, batch_size=16, embedding_dim=16, width=8,
                            objective="pose_contrastive", poses=poses, groups=groups,
                            n_neighbors=2, progress=False)
    assert len(model.loss_history) == 2 and np.all(np.isfinite(model.loss_history))
    with pytest.raises(ValueError, match="needs poses"):
        SmallCNNFeatures(objective="pose_contrastive", epochs=1, progress=False).fit(images)
    ext = SmallCNNFeatures(4, objective="pose_contrastive", epochs=1, embedding_dim=8, width=8,
                           batch_size=16, progress=False).fit(images, poses)
    assert ext.transform(images[:2]).shape == (2, 4)


def test_pixel_pca_mask_uses_only_the_masked_pixels_and_round_trips():
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (40, 16, 16, 3), dtype=np.uint8)
    mask = np.zeros((16, 16), bool)
    mask[:6] = True
    f = PixelPCA(n_components=5, mask=mask).fit(images)
    other = images.copy()
    other[:, 6:] = 0  # pixels outside the mask do not matter
    assert np.array_equal(f.transform(images), f.transform(other))
    assert f.pca_.n_features_in_ == 6 * 16 * 3
    g = features_from_state(f.get_state())
    assert np.array_equal(g.transform(images), f.transform(images))
    with pytest.raises(ValueError, match="mask"):
        PixelPCA(mask=np.ones((8, 8), bool)).fit(images)


@pytest.mark.parametrize("whiten", [False, True])
def test_pca_projection_is_scikit_learns_transform_bit_for_bit(whiten):
    """PixelPCA projects with ``pca_project`` (scikit-learn's formula without its input
    checks, for speed): the numbers must stay those of ``PCA.transform``, also on float32
    pixels and with a component of (almost) zero variance."""
    from localization.features._pca import fit_pca, pca_project

    rng = np.random.default_rng(0)
    x = rng.random((200, 40), dtype=np.float32)
    x[:, 1] = x[:, 0]  # rank-deficient: the last component has (almost) no variance
    pca = fit_pca(x, 40, whiten, 0)
    q = rng.random((7, 40), dtype=np.float32)
    np.testing.assert_array_equal(pca_project(pca, q), pca.transform(q))


def test_shared_stage_splits_transform_and_names_the_network(images, cnn_weights, tmp_path):
    a, b = images[:24], images[24:]
    for ext in extractors(cnn_weights):
        ext.fit(a)
        np.testing.assert_array_equal(ext.head(ext.embed(b)), ext.transform(b))
    pixel, _, enet_raw, enet_pca, cnn = extractors(cnn_weights)
    assert pixel.fit(a).stage_key() is None
    other = SmallCNNFeatures(8, weights=cnn_weights, progress=False).fit(b)
    assert cnn.fit(a).stage_key() == other.stage_key()  # one network, two PCAs
    assert enet_raw.fit(a).stage_key() == enet_pca.fit(b).stage_key()
    assert EfficientNetFeatures(grid=(1, 2), progress=False).fit(a).stage_key() != \
        enet_raw.stage_key()
    retrained = tmp_path / "retrained.pt"
    save_small_cnn(train_small_cnn(images, epochs=1, seed=1, batch_size=16, embedding_dim=32,
                                   width=16, progress=False), retrained)
    assert SmallCNNFeatures(8, weights=str(retrained), progress=False).fit(a).stage_key() != \
        cnn.stage_key()
    loaded = features_from_state(cnn.get_state())
    assert loaded.stage_key() == cnn.stage_key()
    with pytest.raises(ValueError, match="embedded must be CNN embeddings"):
        cnn.head(np.zeros((2, 5)))
    with pytest.raises(ValueError, match="embedded must be pooled features"):
        enet_raw.head(np.zeros((2, 5)))
