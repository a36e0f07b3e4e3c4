"""The look-alike city: twins look the same, landmarks tell them apart, the default is unchanged."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers AppearanceNav-v0)
from envs.lookalike import LookalikeCity, generate_lookalike_city
from envs.robot import ACTUATOR_XML, ROBOT_XML, SENSOR_XML
from envs.scene import generate_city


def _env(**kw) -> gym.Env:
    return gym.make("AppearanceNav-v0", city_layout="lookalike", image_size=(48, 48),
                    max_episode_steps=None, **kw)


def _image(base, pose) -> np.ndarray:
    base.set_pose(np.asarray(pose, dtype=np.float64))
    return base.render_camera().astype(np.float64)


@pytest.fixture(scope="module")
def plain():
    """A look-alike city without landmarks: every twin should look the same."""
    env = _env(scene_seed=3, n_landmarks=0)
    yield env.unwrapped
    env.close()


def test_every_block_is_the_first_block_shifted():
    city = generate_lookalike_city(4, n_landmarks=0)
    per_block = len(city.buildings) // 9
    assert per_block >= 1 and len(city.buildings) == 9 * per_block
    first = np.array([b.center + b.half_size for b in city.buildings[:per_block]])
    for k in range(1, 9):
        row, col = divmod(k, 3)
        block = np.array([b.center + b.half_size for b in city.buildings[k * per_block:(k + 1) * per_block]])
        np.testing.assert_allclose(block, first + [col * city.period, row * city.period, 0, 0, 0, 0])
        assert [b.rgb for b in city.buildings[k * per_block:(k + 1) * per_block]] == \
            [b.rgb for b in city.buildings[:per_block]]
    rng = np.random.default_rng(0)
    pts = rng.uniform(-city.half + 0.2, city.half - 0.2, (2000, 2))
    shifted = pts + [city.period, 0.0]
    keep = np.abs(shifted[:, 0]) <= city.half - 0.2
    np.testing.assert_array_equal(city.free_mask(pts[keep], 0.1), city.free_mask(shifted[keep], 0.1))


def test_twin_poses_render_the_same_image(plain):
    city = plain.city
    rng = np.random.default_rng(1)
    twin_diffs, near_diffs = [], []
    for _ in range(6):
        p = city.random_free_pose(rng, margin=0.4)
        a = _image(plain, p)
        for q in city.twins(p)[:3]:
            if city.is_free(q[0], q[1], 0.4):
                twin_diffs.append(np.abs(a - _image(plain, q)).mean())
        near_diffs.append(np.abs(a - _image(plain, p + [0.0, 0.0, 0.15])).mean())
    assert len(twin_diffs) >= 6
    # a twin looks more like the place than the same place turned by 0.15 rad does, by far
    assert np.median(twin_diffs) < 0.05 * np.median(near_diffs), (twin_diffs, near_diffs)
    assert max(twin_diffs) < 0.3 * min(near_diffs), (twin_diffs, near_diffs)


def test_a_landmark_tells_twins_apart():
    env = _env(scene_seed=3, n_landmarks=1)
    base = env.unwrapped
    city = base.city
    (mark,) = [b for b in city.buildings if b.landmark]
    # on the street south of the landmark building, facing it (north)
    x = mark.center[0]
    y = max(c for c in city.street_centers if c < mark.center[1] - mark.half_size[1])
    p = np.array([x, y, np.pi / 2])
    assert city.is_free(x, y, 0.3)
    a = _image(base, p)
    twins = [q for q in city.twins(p) if city.is_free(q[0], q[1], 0.3)]
    diffs = [np.abs(a - _image(base, q)).mean() for q in twins]
    assert min(diffs) > 5.0, diffs  # mean abs difference in 0..255
    env.close()


def test_info_reports_the_twins_of_the_true_pose():
    env = _env(scene_seed=2)
    _, info = env.reset(seed=0)
    city = env.unwrapped.city
    assert isinstance(city, LookalikeCity) and city.period == pytest.approx(6.0)
    twins = info["twins"]
    assert twins.ndim == 2 and twins.shape[1] == 3 and len(twins) >= 3
    shift = (twins[:, :2] - info["pose"][:2]) / city.period
    np.testing.assert_allclose(shift, np.round(shift), atol=1e-9)
    assert np.all(np.abs(twins[:, :2]) <= city.half) and np.all(twins[:, 2] == info["pose"][2])
    _, _, _, _, info = env.step([0.3, 0.0])
    assert "twins" in info
    env.close()


def test_seeded():
    a, b, c = generate_lookalike_city(7), generate_lookalike_city(7), generate_lookalike_city(8)
    assert a.buildings == b.buildings and a.decor == b.decor
    np.testing.assert_array_equal(a.landmark_blocks, b.landmark_blocks)
    assert a.buildings != c.buildings
    assert sum(x.landmark for x in a.buildings) == 2


def test_default_city_is_unchanged():
    env = gym.make("AppearanceNav-v0", scene_seed=5)
    base = env.unwrapped
    assert base.city_layout == "random" and type(base.city).__name__ == "City"
    want = generate_city(5)
    assert base.city.buildings == want.buildings and base.city.skyline == want.skyline
    assert base.city.to_mjcf(ROBOT_XML, "", ACTUATOR_XML, SENSOR_XML) == \
        want.to_mjcf(ROBOT_XML, "", ACTUATOR_XML, SENSOR_XML)
    _, info = env.reset(seed=0)
    assert "twins" not in info
    env.close()


@pytest.mark.parametrize("kwargs, error, match", [
    ({"city_layout": "mirror"}, ValueError, "city_layout"),
    ({"city_layout": 3}, ValueError, "city_layout"),
    ({"city_layout": "lookalike", "city_size": 9.0}, ValueError, "at least 2 blocks"),
    ({"city_layout": "lookalike", "n_landmarks": 8}, ValueError, "n_landmarks"),
    ({"city_layout": "lookalike", "n_landmarks": -1}, ValueError, "n_landmarks"),
    ({"city_layout": "lookalike", "n_landmarks": 1.5}, TypeError, "n_landmarks"),
])
def test_bad_layout_options_raise_clear_errors(kwargs, error, match):
    with pytest.raises(error, match=match):
        gym.make("AppearanceNav-v0", **kwargs)


def test_twin_queries_validate_their_input():
    city = generate_lookalike_city(0)
    with pytest.raises(ValueError, match="pose"):
        city.twins([0.0, 0.0])
    with pytest.raises(ValueError, match="xy"):
        city.twin_shifts([np.nan, 0.0])
