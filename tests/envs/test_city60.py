"""A 60 m city (nine times the default area) end to end on the env side: layout, street graph,
textures and clip planes, images in every collection mode, the map render, the episode
limit, and the scripted agent on the true pose reaching the far corner."""

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import envs
from agents.evaluation import run_episode
from agents.scripted import ScriptedAgent
from envs.datasets import MODES, collect_dataset
from envs.scene import check_city_layout, generate_city
from localization.wrappers import OracleWrapper


@pytest.fixture(scope="module")
def env60():
    env = gym.make("AppearanceNav-v0", scene_seed=5, city_size=60.0, motion_noise=0.05)
    yield env
    env.close()


def test_60m_city_layout_and_street_graph():
    city = generate_city(5, city_size=60.0)
    assert check_city_layout(60.0) == 9
    assert len(city.street_centers) == 10
    assert city.street_centers[0] == pytest.approx(-29.0)
    assert city.street_centers[-1] == pytest.approx(29.0)
    # 10 streets of 2 m each way over 60 m, less the 100 crossings counted twice
    assert city.street_area() == pytest.approx(2 * 10 * 2.0 * 60.0 - 100 * 4.0)
    assert city.street_area() / generate_city(5).street_area() == pytest.approx(2000 / 256)
    nodes, edges = city.street_graph()
    assert nodes.shape == (100, 2) and len(edges) == 2 * 10 * 9
    route = city.route()  # a Hamiltonian cycle of the 10 x 10 grid: every intersection once
    assert len(route) == 100 and len({tuple(p) for p in route.round(6)}) == 100
    steps = np.hypot(*np.diff(np.vstack([route, route[:1]]), axis=0).T)
    assert np.allclose(steps, steps[0])  # consecutive waypoints are neighbouring crossings
    assert all(city.is_free(x, y) for x, y in route)
    assert len(city.skyline) == 4 * 24  # the default city's density along a longer horizon


def test_impossible_city_sizes_are_refused_by_name():
    with pytest.raises(ValueError, match="city_size=5.0 too small for one block"):
        gym.make("AppearanceNav-v0", city_size=5.0)
    with pytest.raises(ValueError, match="city_size must be finite"):
        check_city_layout(float("inf"))
    with pytest.raises(ValueError, match="city_size"):
        envs.episode_steps(0.0)


def test_textures_keep_the_default_texel_and_the_clip_planes_cover_the_city(env60):
    base = env60.unwrapped
    m = base.model
    tex = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TEXTURE, "ground")
    assert m.tex_width[tex] == m.tex_height[tex] == 2048  # 1024 in the default city
    texel = 2 * base.city.floor_half() / m.tex_width[tex]
    assert texel <= 48.0 / 1024 + 1e-9  # the default city's 4.7 cm
    sky = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TEXTURE, "skyE")
    assert m.tex_width[sky] == 1024
    extent = m.stat.extent
    assert m.vis.map.znear * extent == pytest.approx(0.02, rel=1e-3)  # 2 cm, as by default
    far = base.city.floor_half() - 2.0  # the horizon walls
    farthest = np.hypot(far + base.city.half, far + base.city.half)  # corner to far corner
    assert m.vis.map.zfar * extent > farthest
    default = generate_city(5)
    assert default.ground_pixels() == 1024 and default.horizon_pixels() == (512, 256)


def test_60m_city_renders_views_and_map(env60):
    base = env60.unwrapped
    env60.reset(seed=0)
    c = base.city.street_centers
    images = []
    for x, y, yaw in ((c[0], c[0], 0.0), (c[5], c[9], -np.pi / 2), (c[9], c[4], np.pi)):
        base.set_pose(np.array([x, y, yaw]))
        images.append(base.render_camera().astype(float))
    assert all(img.std() > 10 for img in images)  # not blank: buildings, streets, horizon
    assert np.abs(images[0] - images[1]).mean() > 10  # different places look different
    top = base.render()
    assert top.shape == (768, 768, 3)  # 12.8 pixels a metre, like the default city's 256
    assert (top == base._top_down.GOAL).all(-1).sum() > 20  # the goal disc is visible


@pytest.mark.parametrize("mode", MODES)
def test_60m_city_collects_images_in_every_mode(env60, mode):
    images, poses = collect_dataset(env60, 24, mode, seed=1, progress=False)
    assert images.shape == (24, 64, 64, 3) and poses.shape == (24, 3)
    assert np.all(np.abs(poses[:, :2]) <= 30.0)
    free = env60.unwrapped.city.free_mask(poses[:, :2])
    assert free.all()
    assert len({img.tobytes() for img in images}) > 12
    if mode in ("random", "lanes", "coverage", "grid"):  # spread over the big city
        assert np.abs(poses[:, :2]).max() > 15.0


def test_episode_limit_grows_with_the_city():
    assert envs.episode_steps(20.0) == 500 and envs.episode_steps(60.0) == 1500
    for kwargs, steps in (({}, 500), ({"city_size": 60.0}, 1500),
                          ({"city_size": 60.0, "max_episode_steps": 2000}, 2000),
                          ({"max_episode_steps": 3}, 3)):
        env = gym.make("AppearanceNav-v0", **kwargs)
        assert env.spec.max_episode_steps == steps
        if steps == 3:
            env.reset(seed=0)
            truncated = [env.step(np.zeros(2))[3] for _ in range(3)]
            assert truncated == [False, False, True]
        env.close()
    with pytest.raises(TypeError, match="AppearanceNav"):
        envs.CityTimeLimit(gym.make("CartPole-v1"))


def test_scripted_agent_on_the_true_pose_reaches_the_far_corner():
    """Measured (seed 3): 1355 steps, 114 m driven for a 114.5 m street path, no collision;
    the registered 500 steps of the default city stopped it 60 m short."""
    env = OracleWrapper(gym.make("AppearanceNav-v0", scene_seed=0, city_size=60.0,
                                 motion_noise=0.1))
    city = env.unwrapped.city
    lo, hi = city.street_centers[0], city.street_centers[-1]
    episode = run_episode(env, ScriptedAgent(city), seed=3,
                          options={"pose": np.array([lo, lo + 1.0, np.pi / 2]),
                                   "goal": np.array([hi, hi])})
    env.close()
    assert episode.shortest > 110.0
    assert episode.success and episode.steps <= envs.episode_steps(60.0)
    assert episode.path_ratio < 1.1 and episode.collision_steps == 0
