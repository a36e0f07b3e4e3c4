"""render() of the pose wrappers and the belief renderer: RecordVideo records episodes, the
2-sigma ellipse lands where it should, particles are drawn, nothing is drawn on the step path,
bad inputs raise clear errors."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest

from envs.top_down import top_down_map
from localization.belief_render import COLOURS, BeliefFrame, BeliefRenderer, ellipse_polygon
from localization.wrappers import BeliefWrapper, DeadReckoningWrapper, OracleWrapper

from .conftest import make_env
from .test_wrappers import start_pose

FRAME = (384, 576, 3)


def _mask(img: np.ndarray, colour: str) -> np.ndarray:
    """Pixels of the map (not the side panel's legend) in ``COLOURS[colour]``."""
    return np.all(img[:, :FRAME[0]] == np.array(COLOURS[colour], np.uint8), axis=-1)


@pytest.fixture(scope="module")
def renderer():
    env = make_env()
    out = BeliefRenderer(env.unwrapped.top_down_map())
    env.close()
    return out


def test_ellipse_polygon_is_the_two_sigma_contour():
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    poly = ellipse_polygon([1.0, -2.0], cov, n_sigma=2.0, n=50)
    d = poly - [1.0, -2.0]
    assert poly.shape == (50, 2)
    assert np.allclose(np.einsum("ij,jk,ik->i", d, np.linalg.inv(cov), d), 4.0)
    assert ellipse_polygon([0, 0], np.full((2, 2), np.nan)).shape == (0, 2)


def test_frame_shows_the_ellipse_at_two_sigma(renderer):
    sigma = 0.5  # m: the 2-sigma circle has a radius of 1 m
    mean = np.array([-6.0, 3.0, 0.3])
    img = renderer.draw(BeliefFrame(mean=mean, cov=np.diag([sigma ** 2, sigma ** 2, 0.01])))
    assert img.shape == FRAME and img.dtype == np.uint8
    rows, cols = np.nonzero(_mask(img, "ellipse"))
    (c0, r0), = renderer.to_pixels(mean[:2])
    radius = np.hypot(cols + 0.5 - c0, rows + 0.5 - r0) / renderer.scale
    assert len(radius) > 50  # a 1 m circle is about 120 px round
    assert np.all(np.abs(radius - 2 * sigma) < 0.15), (radius.min(), radius.max())
    plain = renderer.draw(BeliefFrame())
    assert not _mask(plain, "ellipse").any() and not _mask(plain, "belief").any()


def test_frame_shows_particles_path_goal_and_camera(renderer):
    rng = np.random.default_rng(0)
    particles = np.column_stack([rng.uniform(-9, 9, (500, 2)), rng.uniform(-3, 3, 500)])
    image = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    img = renderer.draw(BeliefFrame(particles=particles, weights=np.ones(500),
                                    path=np.array([[-9.0, -9.0], [9.0, -9.0]]),
                                    goal=np.array([5.0, 5.0]), image=image, lines=("hello",)))
    assert _mask(img, "particles").sum() > 500  # 2 x 2 dots, some overlapping
    assert _mask(img, "path").sum() > 300  # 18 m of path, 2 px wide
    assert _mask(img, "goal").any()
    panel = renderer.panel
    assert np.array_equal(img[:panel, renderer.pixels:], np.repeat(np.repeat(image, 6, 0), 6, 1))


def test_max_particles_keeps_the_heaviest():
    env = make_env()
    r = BeliefRenderer(env.unwrapped.top_down_map(), max_particles=1)
    env.close()
    particles = np.array([[-8.0, -8.0, 0.0], [8.0, 8.0, 0.0]])
    img = r.draw(BeliefFrame(particles=particles, weights=np.array([0.1, 0.9])))
    rows, cols = np.nonzero(_mask(img, "particles"))
    (c, rr), = r.to_pixels(particles[1, :2])
    assert len(rows) == 4 and np.all(np.abs(cols - c) <= 1) and np.all(np.abs(rows - rr) <= 1)


@pytest.mark.parametrize("kind", ["ekf", "particles", "oracle", "dead_reckoning"])
def test_wrappers_render_the_belief(localizer, kind):
    env = make_env(max_episode_steps=50)
    if kind in ("ekf", "particles"):
        env = BeliefWrapper(env, localizer, filter=kind,
                            filter_options={"n_particles": 300} if kind == "particles" else None)
    elif kind == "oracle":
        env = OracleWrapper(env, std=(0.3, 0.3, 0.1))
    else:
        env = DeadReckoningWrapper(env, localizer.process_noise_body_,
                                   control_gain=localizer.control_gain_)
    env.reset(seed=1, options={"pose": start_pose(env)})
    for _ in range(5):
        env.step([0.6, 0.1])
    img = env.render()
    assert img.shape == FRAME and img.dtype == np.uint8
    assert _mask(img, "belief").any() and _mask(img, "true").any()
    assert _mask(img, "particles").any() == (kind == "particles")
    # the ellipse's pixels lie within its 2-sigma extent around the mean
    rows, cols = np.nonzero(_mask(img, "ellipse"))
    if len(rows):
        (c0, r0), = env.get_wrapper_attr("_renderer").to_pixels(env.mean[:2])
        reach = 2 * np.sqrt(np.linalg.eigvalsh(env.cov[:2, :2]).max()) * \
            env.get_wrapper_attr("_renderer").scale + 3
        assert np.all(np.hypot(cols - c0, rows - r0) <= reach)
    env.close()


def test_record_video_records_the_belief(localizer, tmp_path):
    iio = pytest.importorskip("imageio.v3")
    pytest.importorskip("moviepy", reason="RecordVideo needs moviepy (the dev extra)")
    env = BeliefWrapper(make_env(max_episode_steps=12), localizer)
    assert env.render_mode == "rgb_array"
    env = gym.wrappers.RecordVideo(env, str(tmp_path / "videos"), episode_trigger=lambda e: e == 0,
                                   disable_logger=True)
    env.reset(seed=2, options={"pose": start_pose(env)})
    env.set_wrapper_attr("planned_path", env.unwrapped.city.route())
    ellipse = []
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step([0.8, 0.15])
        ellipse.append(_mask(env.render(), "ellipse").sum())
        done = terminated or truncated
    env.close()
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1
    frames = iio.imread(videos[0])
    assert frames.shape[1:] == FRAME and len(frames) >= 13  # reset + 12 steps
    change = [np.abs(a.astype(int) - b).mean() for a, b in itertools.pairwise(frames[:13])]
    assert min(change) > 0.2  # every step moves the robot, the camera view and the belief
    assert min(ellipse) > 10  # the 2-sigma ellipse is drawn in every frame


def test_no_drawing_on_the_step_path(localizer, monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("drew a frame nobody asked for")

    monkeypatch.setattr(BeliefRenderer, "draw", fail)
    monkeypatch.setattr(BeliefRenderer, "__init__", fail)
    for mode in (None, "rgb_array"):
        env = BeliefWrapper(make_env(render_mode=mode, max_episode_steps=10), localizer)
        env.reset(seed=0, options={"pose": start_pose(env)})
        for _ in range(3):
            env.step([0.5, 0.0])
        if mode is None:
            assert env.render() is None
        env.close()


def test_bad_render_inputs(localizer):
    env = OracleWrapper(make_env())
    with pytest.raises(ValueError, match="planned_path"):
        env.planned_path = np.zeros((4, 3))
    with pytest.raises(ValueError, match="planned_path"):
        env.planned_path = [[0.0, np.nan]]
    env.planned_path = None
    assert env.planned_path is None
    city = top_down_map(env.unwrapped.city)
    with pytest.raises(ValueError, match="pixels"):
        BeliefRenderer(city, pixels=4)
    with pytest.raises(TypeError, match="panel"):
        BeliefRenderer(city, panel=1.5)

    class NoMap(gym.Env):
        observation_space = make_env().observation_space
        action_space = gym.spaces.Box(-1, 1, (2,))
        render_mode = "rgb_array"

        def reset(self, *, seed=None, options=None):
            return self.observation_space.sample(), {"pose": np.zeros(3)}

    bare = OracleWrapper(NoMap())
    bare.reset()
    with pytest.raises(TypeError, match="top_down_map"):
        bare.render()
