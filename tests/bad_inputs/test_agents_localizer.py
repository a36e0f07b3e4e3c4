"""Bad inputs to agents (planner, scripted agent, navigation features, rewards, lane starts,
pose sources, PPO policy files) and to the AppearanceLocalizer (hyperparameters, inputs,
files)."""

from __future__ import annotations

import io
import json
import warnings
from functools import cached_property
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers AppearanceNav-v0)
from agents.observations import NavigationFeatures, NavigationObservation
from agents.planner import PlannedPath, StreetPlanner
from agents.rewards import StreetProgressReward
from agents.scripted import Navigator, ScriptedAgent
from agents.sources import LaneStart, make_pose_env
from envs.datasets import collect_dataset
from localization.localizer import AppearanceLocalizer
from tests.bad_inputs._cases import Case, check, params

SIZE = (16, 16)
V, T, F = ValueError, TypeError, FileNotFoundError
GOOD_OBS = {"pose_mean": np.array([-8.0, -9.0, 0.0]), "pose_cov": np.array([0.1, 0, 0, 0.1, 0, 0.1]),
            "goal": np.array([8.0, -9.0])}


class Ctx:
    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp

    @cached_property
    def env(self) -> gym.Env:
        return gym.make("AppearanceNav-v0", image_size=SIZE)

    @cached_property
    def city(self):
        return self.env.unwrapped.city

    @cached_property
    def planner(self) -> StreetPlanner:
        return StreetPlanner(self.city)

    @cached_property
    def agent(self) -> ScriptedAgent:
        return ScriptedAgent(self.city)

    @cached_property
    def data(self):
        return collect_dataset(self.env, 120, "grid", progress=False)

    @cached_property
    def localizer(self) -> AppearanceLocalizer:
        loc = AppearanceLocalizer(features_params={"n_components": 6}, noise_folds=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return loc.fit(*self.data)

    def file(self, name: str, content: bytes) -> Path:
        p = self.tmp / name
        p.write_bytes(content)
        return p

    def policy(self, pt: bytes, settings: object) -> Path:
        self.file("p.pt", pt)
        text = settings if isinstance(settings, str) else json.dumps(settings)
        self.file("p.json", text.encode())
        return self.tmp / "p"


@pytest.fixture(scope="module")
def ctx(tmp_path_factory):
    c = Ctx(tmp_path_factory.mktemp("bad_inputs"))
    yield c
    if "env" in c.__dict__:
        c.env.close()


def obs(**kw):
    return {**GOOD_OBS, **kw}


CASES: list[Case] = []

# ---------------------------------------------------------------- planner
for i, (bad, exc, m) in enumerate([(0.0, V, "turn_radius"), (-1.0, V, "turn_radius"),
                                   (np.nan, V, "turn_radius"), ("a", T, "turn_radius")]):
    CASES.append(Case(f"planner-turn_radius-{i}", lambda ctx, b=bad: StreetPlanner(ctx.city, b),
                      exc, m))
CASES += [Case("planner-u_turn_cost", lambda ctx: StreetPlanner(ctx.city, u_turn_cost=-1.0), V,
               "u_turn_cost"),
          Case("planner-city-none", lambda ctx: StreetPlanner(None), T, "city"),
          Case("planner-city-env", lambda ctx: StreetPlanner(ctx.env), T, "city")]
BAD_POINTS = [([0.0], V, "shape"), ([0.0] * 4, V, "shape"), ([[0.0, 0.0]], V, "shape"),
              ([np.nan, 0.0], V, "finite"), ([0.0, np.inf], V, "finite"), ([1j, 0.0], T, "real"),
              ("ab", T, "real"), (None, T, "real"), ([500.0, 0.0], V, "outside the city"),
              ([0.0, -300.0], V, "outside the city"), ([1e6, 1e6, 0.0], V, "outside the city"),
              ([True, False], T, "real"), ([], V, "shape")]
GOAL = [8.0, -9.0]
START = [-8.0, -9.0]
for i, (bad, exc, m) in enumerate(BAD_POINTS):
    CASES.append(Case(f"plan-start-{i}", lambda ctx, b=bad: ctx.planner.plan(b, GOAL), exc,
                      rf"start.*{m}"))
    CASES.append(Case(f"plan-goal-{i}", lambda ctx, b=bad: ctx.planner.plan(START, b), exc,
                      rf"goal.*{m}"))
    CASES.append(Case(f"drive-goal-{i}", lambda ctx, b=bad: ctx.planner.drive([*START, 0.0], b),
                      exc, rf"goal.*{m}"))
    CASES.append(Case(f"nearest-{i}", lambda ctx, b=bad: ctx.planner.nearest_street_point(b),
                      exc, rf"point.*{m}"))
for i, (bad, exc, m) in enumerate([([0.0, 0.0], V, "shape"), ([0.0, 0.0, np.nan], V, "finite"),
                                   ([500.0, 0.0, 0.0], V, "outside"), ([0, 0, 1j], T, "real"),
                                   ([0.0] * 4, V, "shape")]):
    CASES.append(Case(f"drive-pose-{i}", lambda ctx, b=bad: ctx.planner.drive(b, GOAL), exc,
                      rf"pose.*{m}"))
for i, (kw, exc, m) in enumerate([({"waypoints": [[0.0, 0.0, 0.0]]}, V, "waypoints"),
                                  ({"waypoints": np.zeros((0, 2))}, V, "waypoints"),
                                  ({"waypoints": [[np.nan, 0.0]]}, V, "waypoints"),
                                  ({"waypoints": [[1j, 0.0]]}, T, "waypoints"),
                                  ({"waypoints": [[0, 0]], "step": 0.0}, V, "step"),
                                  ({"waypoints": [[0, 0]], "search": -1.0}, V, "search")]):
    CASES.append(Case(f"planned_path-{i}", lambda ctx, k=kw: PlannedPath(**k), exc, m))

# ---------------------------------------------------------------- scripted agent, navigation
for name in ("lookahead", "speed", "w_max", "turn_in_place", "replan_distance"):
    for i, (bad, exc) in enumerate([(0.0, V), (-1.0, V), (np.nan, V), ("1", T)]):
        CASES.append(Case(f"scripted-{name}-{i}",
                          lambda ctx, n=name, b=bad: ScriptedAgent(ctx.city, **{n: b}), exc, name))
CASES.append(Case("navigator-replan", lambda ctx: Navigator(ctx.city, 0.0), V, "replan_distance"))
CASES.append(Case("scripted-plan", lambda ctx: ScriptedAgent(ctx.city, plan="teleport"), V, "plan"))
for i, (bad, exc, m) in enumerate([
        ([1, 2, 3], T, "observation"), (None, T, "observation"), ("obs", T, "observation"),
        ({"image": np.zeros((16, 16, 3))}, V, "pose_mean"),
        ({k: v for k, v in GOOD_OBS.items() if k != "goal"}, V, "goal"),
        (obs(pose_mean=[0.0, 0.0]), V, "pose_mean"), (obs(pose_mean=[np.nan, 0, 0]), V, "pose_mean"),
        (obs(pose_mean=[1j, 0, 0]), T, "pose_mean"), (obs(pose_mean=[500.0, 0, 0]), V, "pose_mean"),
        (obs(pose_cov=np.eye(3)), V, "pose_cov"), (obs(pose_cov=[np.inf] * 6), V, "pose_cov"),
        (obs(goal=[0.0]), V, "goal"), (obs(goal=[-400.0, 0.0]), V, "goal"),
        (obs(goal=["a", "b"]), T, "goal"), (obs(goal=[0, 0, 0]), V, "goal")]):
    CASES.append(Case(f"scripted-act-{i}", lambda ctx, b=bad: ctx.agent.act(b), exc, m))
    CASES.append(Case(f"navfeatures-{i}",
                      lambda ctx, b=bad: NavigationFeatures(ctx.city)(b), exc, m))
for i, (bad, exc) in enumerate([((), V), ((0.0,), V), ((-1.0, 1.0), V), (("a",), T), (1.0, V),
                                ((np.nan,), V)]):
    CASES.append(Case(f"navfeatures-lookaheads-{i}",
                      lambda ctx, b=bad: NavigationFeatures(ctx.city, b), exc, "lookaheads"))
CASES.append(Case("navobs-not-belief", lambda ctx: NavigationObservation(ctx.env), V,
                  "belief observation"))

# ---------------------------------------------------------------- rewards, lane starts, sources
for name in ("step_cost", "collision_penalty", "success_bonus"):
    for i, (bad, exc) in enumerate([(-1.0, V), (np.nan, V), ("0.1", T)]):
        CASES.append(Case(f"reward-{name}-{i}",
                          lambda ctx, n=name, b=bad: StreetProgressReward(ctx.env, **{n: b}),
                          exc, name))
CASES.append(Case("reward-env", lambda ctx: StreetProgressReward(ctx.city), T, "env"))
for name in ("lateral", "heading"):
    for i, (bad, exc) in enumerate([(-0.1, V), (np.inf, V), (None, T)]):
        CASES.append(Case(f"lanestart-{name}-{i}",
                          lambda ctx, n=name, b=bad: LaneStart(ctx.env, **{n: b}), exc, name))
CASES += [
    Case("lanestart-options", lambda ctx: LaneStart(ctx.env).reset(options={"poze": 1}), V,
         "options"),
    Case("lanestart-options-type", lambda ctx: LaneStart(ctx.env).reset(options=[1]), T,
         "options"),
    Case("lanestart-seed", lambda ctx: LaneStart(ctx.env).reset(seed=-2), V, "seed"),
    Case("lanestart-env", lambda ctx: LaneStart(None), T, "env"),
    Case("source-unknown", lambda ctx: make_pose_env("gps"), V, "source"),
    Case("source-none", lambda ctx: make_pose_env(None), V, "source"),
    Case("source-list", lambda ctx: make_pose_env(["oracle"]), V, "source"),
    Case("source-start", lambda ctx: make_pose_env("oracle", start="anywhere"), V, "start"),
    Case("source-no-localizer", lambda ctx: make_pose_env("belief"), V, "localizer"),
    Case("source-dr-no-localizer", lambda ctx: make_pose_env("dead_reckoning"), V, "localizer"),
    Case("source-bad-localizer", lambda ctx: make_pose_env("belief", object()), V, "localizer"),
    Case("source-image_size", lambda ctx: make_pose_env("oracle", image_size=64), T, "image_size"),
    Case("source-scene_seed", lambda ctx: make_pose_env("oracle", scene_seed=-1), V, "scene_seed"),
    Case("source-motion_noise", lambda ctx: make_pose_env("oracle", motion_noise=-1.0), V,
         "motion_noise"),
    Case("source-max_episode_steps", lambda ctx: make_pose_env("oracle", max_episode_steps=0), V,
         "max_episode_steps"),
    Case("source-belief-kwargs", lambda ctx: make_pose_env("oracle", gate_probability=0.9), V,
         "gate_probability"),
]

# ---------------------------------------------------------------- PPO policy files
FMT = "appearance-nav-ppo-policy/1"
SETTINGS = {"format": FMT, "policy_kwargs": {"net_arch": [8]}, "lookaheads": [0.5, 1.0, 2.0]}


def _torch_bytes(obj: object) -> bytes:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _load(pt, settings=SETTINGS):
    from agents.ppo import load_policy

    def call(ctx):
        data = pt() if callable(pt) else pt
        return load_policy(ctx.policy(data, settings))
    return call


def _without(key):
    return {k: v for k, v in SETTINGS.items() if k != key}


WEIGHTS = lambda: _torch_bytes({"x": __import__("torch").zeros(2)})
CASES += [
    Case("policy-missing", lambda ctx: __import__("agents.ppo").ppo.load_policy(ctx.tmp / "none"),
         F, "none"),
    Case("policy-path-type", lambda ctx: __import__("agents.ppo").ppo.load_policy(3), T, "path"),
    Case("policy-empty", _load(b""), V, r"p\.pt is not a policy file"),
    Case("policy-text", _load(b"hello" * 40), V, r"p\.pt is not a policy file"),
    Case("policy-zip-header", _load(b"PK\x03\x04" + b"\0" * 50), V, r"p\.pt is not a policy file"),
    Case("policy-truncated", _load(lambda: WEIGHTS()[:200]), V, r"p\.pt is not a policy file"),
    Case("policy-pickled-object", _load(lambda: _torch_bytes({"w": Path("x")})), V,
         r"p\.pt is not a policy file"),
    Case("policy-not-a-dict", _load(lambda: _torch_bytes([1, 2])), V, r"p\.pt is not a policy file"),
    Case("policy-wrong-weights", _load(WEIGHTS), V, r"p\.pt does not hold"),
    Case("policy-json-missing-lookaheads", _load(WEIGHTS, _without("lookaheads")), V,
         r"p\.json.*lookaheads"),
    Case("policy-json-missing-policy_kwargs", _load(WEIGHTS, _without("policy_kwargs")), V,
         r"p\.json.*policy_kwargs"),
    Case("policy-json-missing-format", _load(WEIGHTS, _without("format")), V, r"p\.json.*format"),
    Case("policy-json-list", _load(WEIGHTS, "[1, 2]"), V, r"p\.json is not a policy"),
    Case("policy-json-invalid", _load(WEIGHTS, "{oops"), V, r"p\.json is not a policy"),
    Case("policy-json-empty", _load(WEIGHTS, ""), V, r"p\.json is not a policy"),
    Case("policy-json-bad-lookaheads", _load(WEIGHTS, {**SETTINGS, "lookaheads": "abc"}), V,
         r"p\.json.*lookaheads"),
    Case("policy-json-neg-lookaheads", _load(WEIGHTS, {**SETTINGS, "lookaheads": [-1.0]}), V,
         r"p\.json.*lookaheads"),
    Case("policy-json-bad-kwargs", _load(WEIGHTS, {**SETTINGS, "policy_kwargs": [1]}), V,
         r"p\.json.*policy_kwargs"),
    Case("policy-json-unknown-kwarg", _load(WEIGHTS, {**SETTINGS, "policy_kwargs": {"nett": 1}}),
         V, r"p\.json.*policy_kwargs"),
]

# ---------------------------------------------------------------- localizer hyperparameters, fit
def fit(ctx_images=None, **params):
    def call(ctx):
        images, poses = ctx.data if ctx_images is None else ctx_images(ctx)
        return AppearanceLocalizer(**params).fit(images, poses)
    return call


for i, (kw, exc, m) in enumerate([
        ({"features": 1}, T, "features"), ({"features": "sift"}, V, "sift"),
        ({"features_params": [1]}, T, "features_params"),
        ({"regressor_params": "x"}, T, "regressor_params"),
        ({"rows": (0.5, 0.2)}, V, "rows"), ({"rows": (0.0, 2.0)}, V, "rows"),
        ({"rows": ("a", "b")}, T, "rows"), ({"rows": (0.0,)}, V, "rows"),
        ({"rows": (np.nan, 1.0)}, V, "rows"), ({"noise_folds": 1}, V, "noise_folds"),
        ({"noise_folds": -1}, V, "noise_folds"), ({"noise_folds": 2.5}, T, "noise_folds"),
        ({"yaw_cut": "north"}, V, "yaw_cut"), ({"yaw_cut": np.nan}, V, "yaw_cut"),
        ({"yaw_cut": None}, T, "yaw_cut"), ({"random_state": -1}, V, "random_state"),
        ({"random_state": 1.5}, T, "random_state")]):
    CASES.append(Case(f"localizer-param-{i}", fit(**kw), exc, m))
X8 = np.zeros((4, 16, 16, 3), np.uint8)
P3 = np.zeros((4, 3))
for i, (images, poses, exc, m) in enumerate([
        (X8.astype(float), P3, V, "images"), (X8 + 0j, P3, T, "images"),
        (X8[0], P3, V, "images"), (X8[..., :1], P3, V, "images"), (X8.astype(str), P3, T, "images"),
        (X8, P3[:3], V, "poses"), (X8, np.full((4, 3), np.nan), V, "poses"),
        (X8, P3 + 1j, T, "poses"), (X8, P3[:, :2], V, "poses"), (X8[:0], P3[:0], V, "images"),
        (X8.astype(bool), P3, T, "images")]):
    CASES.append(Case(f"localizer-fit-data-{i}", fit(lambda ctx, x=images, p=poses: (x, p)),
                      exc, m))
CASES.append(Case("localizer-fit-camera",
                  lambda ctx: AppearanceLocalizer().fit(*ctx.data, camera=1), T, "camera"))

# ---------------------------------------------------------------- localizer inputs (fitted)
IMG = np.zeros((2, 16, 16, 3), np.uint8)
for i, (bad, exc, m) in enumerate([(IMG.astype(float), V, "uint8"), (IMG + 0j, T, "images"),
                                   (np.zeros((2, 32, 32, 3), np.uint8), V, "fitted on"),
                                   (IMG[0, :, :, 0], V, "images"), (IMG[..., :2], V, "images"),
                                   ("image", T, "images"), (IMG[:0], V, "images")]):
    CASES.append(Case(f"localizer-predict-{i}", lambda ctx, b=bad: ctx.localizer.predict(b),
                      exc, m))
CASES += [
    Case("localizer-measure-name", lambda ctx: ctx.localizer.measure(np.zeros(6), "poze"), V,
         "measurement"),
    Case("localizer-measure-nan", lambda ctx: ctx.localizer.measure([np.nan] * 6, "pose"), V,
         r"\bw\b"),
    Case("localizer-measure-complex", lambda ctx: ctx.localizer.measure([1j] * 6, "pose"), T,
         r"\bw\b"),
    Case("localizer-measure-2d", lambda ctx: ctx.localizer.measure(np.zeros((2, 6)), "pose"), V,
         r"\bw\b"),
    Case("localizer-model-name", lambda ctx: ctx.localizer.measurement_model("x"), V,
         "measurement"),
    Case("localizer-model-name-type", lambda ctx: ctx.localizer.measurement_model(["pose"]), V,
         "measurement"),
    Case("localizer-unfitted-predict", lambda ctx: AppearanceLocalizer().predict(IMG), V,
         "not fitted"),
    Case("localizer-unfitted-save", lambda ctx: AppearanceLocalizer().save(ctx.tmp / "u.npz"), V,
         "not fitted"),
    Case("localizer-process-noise-missing",
         lambda ctx: ctx.localizer.process_noise([0.0, 0.0, 0.0]), V, "process noise"),
]

# ---------------------------------------------------------------- localizer files
def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _load_loc(name, content):
    return lambda ctx: AppearanceLocalizer.load(ctx.file(name, content))


CASES += [
    Case("loc-file-missing", lambda ctx: AppearanceLocalizer.load(ctx.tmp / "nope.npz"), F,
         "nope"),
    Case("loc-file-path-type", lambda ctx: AppearanceLocalizer.load(None), T, "path"),
    Case("loc-file-empty", _load_loc("empty.npz", b""), V, "empty.npz"),
    Case("loc-file-text", _load_loc("text.npz", b"not a localizer"), V, "text.npz"),
    Case("loc-file-truncated", _load_loc("trunc.npz", _npz(a=np.zeros(100))[:60]), V, "trunc.npz"),
    Case("loc-file-no-settings", _load_loc("nos.npz", _npz(a=np.zeros(3))), V, "nos.npz"),
    Case("loc-file-settings-list", _load_loc("list.npz", _npz(settings=np.array("[1]"))), V,
         "list.npz"),
    Case("loc-file-format", _load_loc("fmt.npz", _npz(settings=np.array('{"format": "x"}'))), V,
         "fmt.npz"),
    Case("loc-file-missing-key", _load_loc("key.npz", _npz(settings=np.array(json.dumps(
        {"format": "appearance-nav-localizer/2"})))), V, "key.npz"),
    Case("loc-file-pickle", _load_loc("pkl.npz", _npz(a=np.array([None], dtype=object))), V,
         "pkl.npz"),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input_raises_a_clear_error(case, ctx):
    check(case, ctx)


# ---------------------------------------------------------------- valid boundary cases
def test_save_creates_the_missing_folder(ctx):
    path = ctx.tmp / "new" / "deeper" / "localizer.npz"
    ctx.localizer.save(path)
    loaded = AppearanceLocalizer.load(path)
    np.testing.assert_allclose(loaded.predict(ctx.data[0][:3]), ctx.localizer.predict(ctx.data[0][:3]),
                               equal_nan=True)


@pytest.mark.parametrize("point", [[8.0, -9.0], (8, -9), np.array([8.0, -9.0, 1.0]),
                                   np.array([8, -9], np.int64), [10.5, -9.0]])
def test_valid_points_keep_working(ctx, point):
    path = ctx.planner.plan([-8.0, -9.0], point)
    assert path.shape[1] == 2


def test_valid_observation_keeps_working(ctx):
    ctx.agent.reset()
    u = ctx.agent.act({k: list(v) for k, v in GOOD_OBS.items()})
    assert u.shape == (2,) and u.dtype == np.float32


def test_single_image_and_row_vector_features_keep_working(ctx):
    loc = ctx.localizer
    assert loc.predict(ctx.data[0][0]).shape == (1, 3)
    w = loc.transform(ctx.data[0][:1])
    np.testing.assert_array_equal(loc.measure(w, "pose"), loc.measure(w[0], "pose"))
