"""The SmallCNN training job's condition-randomised data and the packaged checkpoints."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers AppearanceNav-v0)
from localization.features.weights import MODES, small_cnn_weights
from localization.workflows.small_cnn_training import (
    SmallCNNTrainConfig,
    other_looks,
    train_small_cnn_job,
)


def test_other_looks_renders_each_pose_again_in_new_looks():
    env = gym.make("AppearanceNav-v0", scene_seed=3, image_size=(32, 32), conditions="random")
    try:
        _, info = env.reset(seed=5)
        base = env.unwrapped
        poses = np.array([info["pose"] + [0.0, 0.0, 2.0 * i] for i in range(3)])
        images = []
        for p in poses:
            base.set_pose(p)
            images.append(base.render_camera())
        images = np.asarray(images)
        out, out_poses = other_looks(env, images, poses, looks=3)
    finally:
        env.close()
    assert out.shape == (9, 32, 32, 3) and out.dtype == np.uint8
    np.testing.assert_array_equal(out[:3], images)  # the originals come first
    np.testing.assert_array_equal(out_poses, np.tile(poses, (3, 1)))
    for i in range(3):  # the same pose, another look
        assert not np.array_equal(out[i], out[3 + i])
        assert not np.array_equal(out[3 + i], out[6 + i])


def test_one_look_returns_the_input_unchanged():
    images = np.zeros((2, 8, 8, 3), np.uint8)
    poses = np.zeros((2, 3))
    out, out_poses = other_looks(None, images, poses, looks=1)
    assert out is images and out_poses is poses


@pytest.mark.parametrize("looks, conditions, match", [
    (0, "random", "looks_per_pose must be >= 1"),
    (2, "default", "needs conditions='random'"),
])
def test_bad_looks_per_pose_is_named(looks, conditions, match, tmp_path):
    args = SmallCNNTrainConfig(looks_per_pose=looks, conditions=conditions, synthetic=True,
                               out=str(tmp_path / "w.pt"))
    with pytest.raises(ValueError, match=match):
        train_small_cnn_job(args)


@pytest.mark.parametrize("mode", MODES)
def test_packaged_perspective_checkpoints_exist_with_their_record(mode):
    path = small_cnn_weights("perspective", mode)
    assert path.is_file() and path.with_suffix(".pt.json").is_file()


def test_conditions_checkpoint_loads_and_embeds():
    from localization.features import make_features

    feats = make_features("small_cnn", n_components=4,
                          weights=str(small_cnn_weights("perspective", "conditions")))
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, size=(12, 64, 64, 3), dtype=np.uint8)
    W = feats.fit(images).transform(images)
    assert W.shape == (12, 4) and np.all(np.isfinite(W))


def test_unknown_mode_and_missing_checkpoint_say_what_to_do():
    with pytest.raises(ValueError, match="mode must be one of route, random, conditions"):
        small_cnn_weights("perspective", "night")
    with pytest.raises(FileNotFoundError, match="--mode random --conditions random"):
        small_cnn_weights("fisheye", "conditions")
