"""The camera registry and the perspective camera."""

import envs  # noqa: F401  (first: chooses MUJOCO_GL before mujoco is imported)

# isort: split
import mujoco
import numpy as np
import pytest

from envs import AppearanceNavEnv
from envs.cameras import CAMERAS, check_image_size, make_camera


def test_registry_and_unknown_name():
    assert "perspective" in CAMERAS
    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><camera name='ego'/></worldbody></mujoco>")
    with pytest.raises(ValueError, match="known cameras: .*perspective"):
        make_camera("pinhole", model, (32, 32))


def test_perspective_renders_and_closes():
    env = AppearanceNavEnv(scene_seed=0, image_size=(24, 40))
    env.reset(seed=0)
    cam = make_camera("perspective", env.model, (48, 80))
    img = cam.render(env.data)
    assert img.shape == (48, 80, 3) and img.dtype == np.uint8 and img.std() > 5
    cam.close()
    cam.close()  # idempotent
    with pytest.raises(RuntimeError):
        cam.render(env.data)
    env.close()


@pytest.mark.parametrize("name", sorted(set(CAMERAS) - {"perspective"}))
def test_other_registered_cameras_work_in_env(name):
    env = AppearanceNavEnv(scene_seed=0, camera=name, image_size=(32, 32))
    obs, _ = env.reset(seed=0)
    assert obs["image"].shape == (32, 32, 3) and obs["image"].dtype == np.uint8
    env.close()


@pytest.mark.parametrize("size", [(15, 64), (64, 2000), (64, 64, 3)])
def test_bad_image_sizes(size):
    with pytest.raises(ValueError, match="image_size"):
        check_image_size(size)


@pytest.mark.parametrize("size", [(64.0, 64), (True, 64), "64x64"])
def test_wrong_type_image_sizes(size):
    with pytest.raises(TypeError, match="image_size"):
        check_image_size(size)
