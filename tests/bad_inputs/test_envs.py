"""Bad inputs to envs: gym.make kwargs, reset options, step actions, set_pose, datasets,
lanes, the city generator and the motion model."""

from __future__ import annotations

from functools import cached_property

import gymnasium as gym
import numpy as np
import pytest

import envs
from envs.datasets import collect_dataset, drive_route, drive_streets, grid_poses
from envs.lanes import lane_poses, street_tour
from envs.motion_model import UnicycleModel
from envs.scene import generate_city
from tests.bad_inputs._cases import Case, check, params

SIZE = (16, 16)


class Ctx:
    @cached_property
    def env(self) -> gym.Env:
        env = gym.make("AppearanceNav-v0", image_size=SIZE)
        env.reset(seed=0)
        return env

    @cached_property
    def city(self):
        return self.env.unwrapped.city


@pytest.fixture(scope="module")
def ctx():
    c = Ctx()
    yield c
    if "env" in c.__dict__:
        c.env.close()


def make(**kw):
    return lambda ctx: gym.make("AppearanceNav-v0", **{"image_size": SIZE, **kw})


CASES: list[Case] = []
V, T = ValueError, TypeError

# ---------------------------------------------------------------- gym.make kwargs
for i, (bad, exc) in enumerate([(-1, V), (-(2 ** 40), V), (1.5, T), (1.0, T), ("0", T),
                                 (None, T), (True, T), ([0], T), (np.float64(2.0), T),
                                 (1j, T), (np.int64(-3), V)]):
    CASES.append(Case(f"make-scene_seed-{i}", make(scene_seed=bad), exc, "scene_seed"))
for i, (bad, exc, m) in enumerate([(1, T, "camera"), (None, T, "camera"),
                                   ("pinhole", V, "camera"), (["perspective"], T, "camera"),
                                   ("", V, "camera"), ("Perspective", V, "camera")]):
    CASES.append(Case(f"make-camera-{i}", make(camera=bad), exc, m))
for i, (bad, exc) in enumerate([(64, T), ("64x64", T), ((15, 64), V), ((64, 2000), V),
                                 ((64.0, 64), T), ((True, 64), T), ((64, 64, 3), V), (None, T),
                                 ((0, 0), V), ((-16, 16), V), ((16,), V), ((16, "16"), T),
                                 (np.array([8, 8]), V), ((16, None), T)]):
    CASES.append(Case(f"make-image_size-{i}", make(image_size=bad), exc, "image_size"))
for i, (bad, exc) in enumerate([(-1.0, V), (-1e-9, V), (np.nan, V), (np.inf, V), ("0.1", T),
                                 (None, T), (True, T), (1j, T), ([0.1], T)]):
    CASES.append(Case(f"make-motion_noise-{i}", make(motion_noise=bad), exc, "motion_noise"))
for i, (bad, exc) in enumerate([("human", V), ("rgb_array_list", V), ("ansi", V), ("", V),
                                 ("RGB_ARRAY", V)]):
    CASES.append(Case(f"make-render_mode-{i}", make(render_mode=bad), exc, "render_mode"))
for i, (bad, exc) in enumerate([(0, V), (-5, V), (1.5, T), ("10", T), (True, T)]):
    CASES.append(Case(f"make-max_episode_steps-{i}",
                      lambda ctx, b=bad: envs.AppearanceNavEnv(image_size=SIZE, max_episode_steps=b),
                      exc, "max_episode_steps"))
for i, (bad, exc) in enumerate([(0, V), (-1, V), (2.5, T), (10.0, T), ("10", T), (None, T)]):
    CASES.append(Case(f"make-frame_skip-{i}", make(frame_skip=bad), exc, "frame_skip"))
for name in ("city_size", "block_size", "street_width"):
    for i, (bad, exc) in enumerate([(0.0, V), (-4.0, V), (np.nan, V), (np.inf, V), ("4", T),
                                    (None, T)]):
        CASES.append(Case(f"make-{name}-{i}", make(**{name: bad}), exc, name))
CASES.append(Case("make-city_size-too-small", make(city_size=3.0), V, "city_size"))
CASES.append(Case("make-unknown-kwarg", make(scene_sed=1), T, "scene_sed"))
CASES.append(Case("make-unknown-kwarg-2", make(cam="perspective"), T, "cam"))

# ---------------------------------------------------------------- reset
for i, (bad, exc) in enumerate([(-1, V), (1.5, T), ("0", T), (True, T), ([0], T),
                                 (np.float32(1), T), (np.int64(-1), V)]):
    CASES.append(Case(f"reset-seed-{i}", lambda ctx, b=bad: ctx.env.reset(seed=b), exc, "seed"))
for i, bad in enumerate(["pose", [1, 2], 5, ("pose", [0, 0, 0])]):
    CASES.append(Case(f"reset-options-type-{i}", lambda ctx, b=bad: ctx.env.reset(options=b),
                      T, "options"))
for i, bad in enumerate([{"poze": [0, 0, 0]}, {"Pose": None}, {"start": [0, 0, 0]},
                         {"pose": None, "goals": [0, 0]}, {1: 2}]):
    CASES.append(Case(f"reset-options-key-{i}", lambda ctx, b=bad: ctx.env.reset(options=b),
                      V, "options"))
for key, dim in (("pose", 3), ("goal", 2)):
    bad_points = [([0.0] * (dim - 1), V, "shape"), ([0.0] * (dim + 1), V, "shape"),
                  ([[0.0] * dim], V, "shape"), ([np.nan] + [0.0] * (dim - 1), V, "finite"),
                  ([np.inf] + [0.0] * (dim - 1), V, "finite"),
                  ([1j] + [0.0] * (dim - 1), T, "real"), (["a"] * dim, T, "real"),
                  ("xy", T, "real"), ([500.0] + [0.0] * (dim - 1), V, "outside the city"),
                  ([0.0, -300.0] + [0.0] * (dim - 2), V, "outside the city"),
                  ([None] * dim, T, "real"), ([True] * dim, T, "real"),
                  ([[0.0], [0.0, 1.0]] + [0.0] * (dim - 2), V, "ragged")]
    for i, (bad, exc, m) in enumerate(bad_points):
        CASES.append(Case(f"reset-{key}-{i}",
                          lambda ctx, k=key, b=bad: ctx.env.reset(seed=0, options={k: b}),
                          exc, rf'options\["{key}"\].*{m}'))

# ---------------------------------------------------------------- step
for i, (bad, exc) in enumerate([([np.nan, 0.0], V), ([0.0, np.inf], V), ([0.0], V),
                                 ([0.0, 0.0, 0.0], V), (np.zeros((2, 1)), V), ([], V),
                                 ("ab", T), (None, T), ([1j, 0.0], T),
                                 (np.array([1 + 1j, 0]), T), (np.array([0.5 + 0j, 0]), T),
                                 ([True, False], T), (np.array([True, False]), T),
                                 (np.array([None, 0.0], dtype=object), T), ({"v": 1}, T),
                                 ([[1.0, 0.0]], V), (np.float64(1.0), V),
                                 ([[1.0], [0.0, 1.0]], V), (["1", "0"], T)]):
    CASES.append(Case(f"step-action-{i}", lambda ctx, b=bad: ctx.env.step(b), exc, "action"))

# ---------------------------------------------------------------- set_pose
for i, (bad, exc) in enumerate([([0.0, 0.0], V), ([np.nan, 0.0, 0.0], V), ([1j, 0.0, 0.0], T),
                                 ("abc", T), (None, T), ([0.0] * 4, V), (np.zeros((1, 3)), V)]):
    CASES.append(Case(f"set_pose-{i}", lambda ctx, b=bad: ctx.env.unwrapped.set_pose(b),
                      exc, "pose"))

# ---------------------------------------------------------------- datasets
def collect(**kw):
    base = {"n": 2, "mode": "random", "progress": False}
    return lambda ctx: collect_dataset(ctx.env, **{**base, **kw})


for i, (bad, exc) in enumerate([(0, V), (-1, V), (1.5, T), (2.0, T), ("10", T), (None, T),
                                (True, T)]):
    CASES.append(Case(f"collect-n-{i}", collect(n=bad), exc, r"\bn\b"))
for i, (bad, exc) in enumerate([("spiral", V), ("Grid", V), (1, V), (None, V), ("", V)]):
    CASES.append(Case(f"collect-mode-{i}", collect(mode=bad), exc, "mode"))
for i, (bad, exc) in enumerate([(-1, V), (1.5, T), ("0", T), (None, T)]):
    CASES.append(Case(f"collect-seed-{i}", collect(seed=bad), exc, "seed"))
for i, (bad, exc) in enumerate([(0, V), (-8, V), (2.5, T), ("8", T)]):
    CASES.append(Case(f"collect-n_headings-{i}", collect(mode="grid", n_headings=bad), exc,
                      "n_headings"))
CASES += [
    Case("collect-progress", collect(progress="yes"), T, "progress"),
    Case("collect-lane-option-wrong-mode", collect(lanes="route"), V, "lanes"),
    Case("collect-lane-option-unknown", collect(mode="lanes", lane="route"), V, "lane"),
    Case("collect-lane-option-lanes", collect(mode="lanes", lanes="roads"), V, "lanes"),
    Case("collect-lane-option-lateral", collect(mode="lanes", lateral=-1.0), V, "lateral"),
    Case("collect-lane-option-heading", collect(mode="lanes", heading=np.nan), V, "heading"),
    Case("collect-lane-option-turn_radius", collect(mode="lanes", turn_radius=0.0), V,
         "turn_radius"),
    Case("collect-lane-option-turn_weight", collect(mode="lanes", turn_weight="8"), T,
         "turn_weight"),
    Case("collect-env-none", lambda ctx: collect_dataset(None, 2, progress=False), T, "env"),
    Case("collect-env-str", lambda ctx: collect_dataset("AppearanceNav-v0", 2), T, "env"),
    Case("grid_poses-n", lambda ctx: grid_poses(ctx.city, 0), V, r"\bn\b"),
    Case("grid_poses-n_headings", lambda ctx: grid_poses(ctx.city, 4, n_headings=0), V,
         "n_headings"),
    Case("grid_poses-margin", lambda ctx: grid_poses(ctx.city, 4, margin=-1.0), V, "margin"),
    Case("drive_route-n", lambda ctx: drive_route(ctx.env, 0, progress=False), V, r"\bn\b"),
    Case("drive_route-n-float", lambda ctx: drive_route(ctx.env, 2.5), T, r"\bn\b"),
    Case("drive_route-seed", lambda ctx: drive_route(ctx.env, 2, seed=-1), V, "seed"),
    Case("drive_route-start", lambda ctx: drive_route(ctx.env, 2, start=0.5), T, "start"),
    Case("drive_route-env", lambda ctx: drive_route(ctx.city, 2), T, "env"),
    Case("drive_streets-n", lambda ctx: drive_streets(ctx.env, -3), V, r"\bn\b"),
    Case("drive_streets-speed", lambda ctx: drive_streets(ctx.env, 2, speed=0.0), V, "speed"),
    Case("drive_streets-speed-nan", lambda ctx: drive_streets(ctx.env, 2, speed=np.nan), V,
         "speed"),
    Case("drive_streets-progress", lambda ctx: drive_streets(ctx.env, 2, progress=None), T,
         "progress"),
]

# ---------------------------------------------------------------- lanes, city, motion model
RNG = np.random.default_rng(0)
CASES += [
    Case("lane_poses-n", lambda ctx: lane_poses(ctx.city, 0, RNG), V, r"\bn\b"),
    Case("lane_poses-n-float", lambda ctx: lane_poses(ctx.city, 1.5, RNG), T, r"\bn\b"),
    Case("lane_poses-lanes", lambda ctx: lane_poses(ctx.city, 2, RNG, lanes="all"), V, "lanes"),
    Case("lane_poses-lateral", lambda ctx: lane_poses(ctx.city, 2, RNG, lateral=-0.1), V,
         "lateral"),
    Case("lane_poses-margin", lambda ctx: lane_poses(ctx.city, 2, RNG, margin=np.inf), V,
         "margin"),
    Case("street_tour-length", lambda ctx: street_tour(ctx.city, 0.0, RNG), V, "length"),
    Case("street_tour-length-str", lambda ctx: street_tour(ctx.city, "10", RNG), T, "length"),
    Case("city-seed", lambda ctx: generate_city(-1), V, "seed"),
    Case("city-seed-float", lambda ctx: generate_city(0.5), T, "seed"),
    Case("city-max_height", lambda ctx: generate_city(0, max_height=0.0), V, "max_height"),
    Case("city-n_landmarks", lambda ctx: generate_city(0, n_landmarks=-1), V, "n_landmarks"),
    Case("city-n_landmarks-float", lambda ctx: generate_city(0, n_landmarks=1.5), T,
         "n_landmarks"),
]
for i, (bad, exc) in enumerate([(0.0, V), (-0.1, V), (np.nan, V), ("0.1", T), (None, T)]):
    CASES.append(Case(f"motion-dt-{i}", lambda ctx, b=bad: UnicycleModel(b), exc, "dt"))
F = UnicycleModel(0.1)
for method in ("predict", "jacobian_pose", "jacobian_control"):
    for i, (pose, u, exc, m) in enumerate([
            ([0, 0], [1, 0], V, "pose"), ([0, 0, np.nan], [1, 0], V, "pose"),
            ([0, 0, 1j], [1, 0], T, "pose"), ("abc", [1, 0], T, "pose"),
            ([0, 0, 0], [1], V, r"\bu\b"), ([0, 0, 0], [np.inf, 0], V, r"\bu\b"),
            ([0, 0, 0], [1j, 0], T, r"\bu\b")]):
        CASES.append(Case(f"motion-{method}-{i}",
                          lambda ctx, name=method, p=pose, c=u: getattr(F, name)(p, c), exc, m))


# ---------------------------------------------------------------- conditions
for i, (bad, exc, m) in enumerate([
        ("dawn", V, "preset"), ("Night", V, "preset"), ("", V, "preset"), (3, T, "conditions"),
        (["night"], T, "conditions"), ({"preset": "dawn"}, V, "preset"),
        ({"preset": 1}, T, "preset"), ({"preset": "night", "fogg": (1, 2)}, V, "fogg"),
        ({"noise": -0.1}, V, "noise"), ({"noise": "0.1"}, T, "noise"),
        ({"noise": np.nan}, V, "noise"), ({"vehicles": 100}, V, "vehicles"),
        ({"vehicles": 1.5}, T, "vehicles"), ({"pedestrians": -1}, V, "pedestrians"),
        ({"fog": (5.0, 2.0)}, V, "fog"), ({"fog": (1.0,)}, V, "fog"),
        ({"sun": [1.0, 2.0]}, V, "sun"), ({"sun": [3.0, 0.0, 0.0]}, V, "sun"),
        ({"sun_direction": [0, 0, 0]}, V, "sun_direction"), ({"exposure": 0.0}, V, "exposure"),
        ({"ground": ["a", "b", "c"]}, T, "ground"), ({"season": 0.5}, T, "season"),
        ({"preset": "random", "lamps": 5.0}, V, "lamps"), ({1: 2}, V, "conditions"),
        ({"preset": "dusk", "camera": "random-ish"}, V, "camera"),
        ({"preset": "random", "camera": "random"}, V, "camera"),
        ({"preset": envs.conditions.PRESETS["dusk"], "noise": 2.0}, V, "noise")]):
    CASES.append(Case(f"make-conditions-{i}", make(conditions=bad), exc, m))
CASES += [
    Case("set_conditions-default-env",
         lambda ctx: ctx.env.unwrapped.set_conditions(envs.conditions.PRESETS["night"]), V,
         "without conditions"),
    Case("set_conditions-type", lambda ctx: ctx.env.unwrapped.set_conditions("night"), T,
         "Conditions"),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input_raises_a_clear_error(case, ctx):
    check(case, ctx)


# ---------------------------------------------------------------- valid boundary cases
@pytest.mark.parametrize("seed", [0, np.int64(0), np.int32(3), np.uint8(7), 2 ** 40])
def test_valid_seeds_keep_working(ctx, seed):
    obs, _ = ctx.env.reset(seed=seed)
    assert obs["image"].shape == (*SIZE, 3)
    assert generate_city(seed).seed == int(seed)


def test_numpy_seed_gives_the_same_reset_as_int(ctx):
    a = ctx.env.reset(seed=np.int64(5))[1]["pose"]
    b = ctx.env.reset(seed=5)[1]["pose"]
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("action", [[0.0, 0.0], (1, -1), np.array([5.0, -9.0], np.float32),
                                    np.array([1, 0], np.int64), [np.float16(0.5), 0]])
def test_valid_actions_keep_working(ctx, action):
    ctx.env.reset(seed=0)
    ctx.env.step(action)


@pytest.mark.parametrize("options", [None, {}, {"pose": None}, {"goal": None},
                                     {"pose": None, "goal": None}])
def test_valid_options_keep_working(ctx, options):
    ctx.env.reset(seed=0, options=options)


def test_reset_does_not_modify_the_callers_pose(ctx):
    pose = np.array([-3.0, -9.0, 4.0])
    ctx.env.reset(seed=0, options={"pose": pose})
    np.testing.assert_array_equal(pose, [-3.0, -9.0, 4.0])


def test_valid_boundaries_of_constructor():
    env = envs.AppearanceNavEnv(scene_seed=np.int64(0), image_size=(np.int64(16), 16),
                                motion_noise=0, max_episode_steps=1, frame_skip=1,
                                render_mode=None)
    env.close()
    assert UnicycleModel(np.float32(0.1)).dt == pytest.approx(0.1)


# ---------------------------------------------------------------- metrics (numpy only)
@pytest.mark.parametrize("bad, exc", [(np.ones(3) + 1j, TypeError), (["a", "b", "c"], TypeError),
                                      (np.array([True, False, True]), TypeError),
                                      ([[1.0], [1.0, 2.0], [3.0]], ValueError),
                                      (np.ones(4), ValueError), ([np.nan] * 3, ValueError)])
@pytest.mark.parametrize("metric", ["rmse", "rrmse"])
def test_metrics_name_a_bad_estimate(metric, bad, exc):
    from localization import metrics

    with pytest.raises(exc, match="theta_hat"):
        getattr(metrics, metric)(bad, np.array([0.1, 0.5, 0.9]))

