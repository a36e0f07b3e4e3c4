"""Bad inputs to the filtering toolkit (PoseEKF, measurement models, noise maths, BeliefFilter),
the belief wrappers and the feature extractors."""

from __future__ import annotations

import warnings
from functools import cached_property

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers AppearanceNav-v0)
from envs.datasets import collect_dataset, drive_route
from envs.motion_model import UnicycleModel
from localization.features import PixelPCA, make_features
from localization.filtering import (
    BeliefFilter,
    FunctionMeasurement,
    PoseEKF,
    PoseMeasurement,
    chi2_band,
    control_noise_Q,
    correlation_time,
    estimate_process_noise,
    inflate,
    robust_covariance,
    world_process_noise,
)
from localization.localizer import AppearanceLocalizer
from localization.wrappers import BeliefWrapper, DeadReckoningWrapper, OracleWrapper
from tests.bad_inputs._cases import Case, check, params

SIZE = (16, 16)
V, T = ValueError, TypeError
F = UnicycleModel(0.1)
I3 = np.eye(3) * 0.01
X0 = np.zeros(3)


class Ctx:
    @cached_property
    def env(self) -> gym.Env:
        return gym.make("AppearanceNav-v0", image_size=SIZE)

    @cached_property
    def localizer(self) -> AppearanceLocalizer:
        images, poses = collect_dataset(self.env, 300, "lanes", seed=0, progress=False,
                                        lanes="route")
        loc = AppearanceLocalizer(features_params={"n_components": 6}, noise_folds=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            loc.fit(images, poses)
            loc.fit_noise(self.env.unwrapped.motion_model,
                          *drive_route(self.env, 240, seed=1, progress=False))
        return loc

    @cached_property
    def ekf(self) -> PoseEKF:
        return PoseEKF(F, I3, X0, I3)

    @cached_property
    def images(self) -> np.ndarray:
        return np.zeros((4, *SIZE, 3), np.uint8)


@pytest.fixture(scope="module")
def ctx():
    c = Ctx()
    yield c
    if "env" in c.__dict__:
        c.env.close()


def belief(ctx, **kw):
    args = {"localizer": ctx.localizer, "motion_model": F, "measurement": "pose"} | kw
    return BeliefFilter(**args)


CASES: list[Case] = []
BAD_COV = [(np.eye(2), V, "shape"), (np.full((3, 3), np.nan), V, "finite|NaN"),
           (-np.eye(3), V, "definite|semi"), (np.array([[1, 2, 0], [0, 1, 0], [0, 0, 1.0]]), V,
                                              "symmetric"),
           ("eye", T, "real"), (np.eye(3) * 1j, T, "real|complex")]
for i, (bad, exc, m) in enumerate(BAD_COV):
    CASES.append(Case(f"ekf-P0-{i}", lambda ctx, b=bad: PoseEKF(F, I3, X0, b), exc, rf"P0.*{m}"))
    CASES.append(Case(f"ekf-Q-{i}", lambda ctx, b=bad: PoseEKF(F, b, X0, I3), exc, rf"Q.*{m}"))
    CASES.append(Case(f"posemeas-R-{i}", lambda ctx, b=bad: PoseMeasurement(b), exc, rf"R.*{m}"))
BAD_X = [([0.0, 0.0], V, "shape|3"), ([np.nan, 0, 0], V, "finite|NaN"), ([0, 0, 1j], T,
                                                                        "real|complex"),
         ("abc", T, "real"), (None, T, "real")]
for i, (bad, exc, m) in enumerate(BAD_X):
    CASES.append(Case(f"ekf-x0-{i}", lambda ctx, b=bad: PoseEKF(F, I3, b, I3), exc, rf"x0.*{m}"))
for i, bad in enumerate([0.0, 1.0, -0.5, 2.0, np.nan]):
    CASES.append(Case(f"ekf-gate-{i}", lambda ctx, b=bad: PoseEKF(F, I3, X0, I3, b), V,
                      "gate_probability"))
CASES.append(Case("ekf-gate-str", lambda ctx: PoseEKF(F, I3, X0, I3, "0.9"), T,
                  "gate_probability"))
CASES.append(Case("ekf-motion-none", lambda ctx: PoseEKF(None, I3, X0, I3), T, "motion_model"))
for i, (bad, exc, m) in enumerate([([0.0], V, "u|control"), ([np.nan, 0.0], V, "u|control"),
                                   ([1j, 0.0], T, "u|control"), ([0.0, 0.0, 0.0], V,
                                                                 "u|control")]):
    CASES.append(Case(f"ekf-predict-u-{i}", lambda ctx, b=bad: ctx.ekf.predict(b), exc, m))
for i, (bad, exc, m) in enumerate([([0.0, 0.0], V, "z"), ([np.nan, 0, 0], V, "z"),
                                   ([1j, 0, 0], T, "z")]):
    CASES.append(Case(f"ekf-update-z-{i}",
                      lambda ctx, b=bad: ctx.ekf.update(b, PoseMeasurement(I3)), exc, m))
CASES.append(Case("ekf-update-model", lambda ctx: ctx.ekf.update(X0, None), T, "model"))
for i, (bad, exc, m) in enumerate([([1.0, 1.0, 1.0], V, "true_pose|shape"),
                                   ([np.nan, 0, 0], V, "true_pose")]):
    if i == 0:
        bad = [1.0, 1.0]
    CASES.append(Case(f"ekf-nees-{i}", lambda ctx, b=bad: ctx.ekf.nees(b), exc, m))
CASES += [
    Case("fm-h", lambda ctx: FunctionMeasurement(None, lambda x: np.eye(3), I3), T, "h"),
    Case("fm-H", lambda ctx: FunctionMeasurement(lambda x: x, 3, I3), T, "H"),
    Case("fm-R-1d", lambda ctx: FunctionMeasurement(lambda x: x, lambda x: np.eye(3), [1.0]), V,
         "R"),
    Case("control-M", lambda ctx: control_noise_Q(F, np.eye(3)), V, "M"),
    Case("control-Q0", lambda ctx: control_noise_Q(F, np.eye(2), np.eye(2)), V, "Q0"),
    Case("chi2-dof", lambda ctx: chi2_band(0, 10), V, "dof"),
    Case("chi2-n", lambda ctx: chi2_band(3, 0), V, "n"),
    Case("chi2-prob", lambda ctx: chi2_band(3, 10, 1.5), V, "prob"),
    Case("robust-1d", lambda ctx: robust_covariance(np.zeros(10)), V, "residuals"),
    Case("robust-few", lambda ctx: robust_covariance(np.zeros((3, 3))), V, "residuals"),
    Case("robust-complex", lambda ctx: robust_covariance(np.zeros((50, 3)) * 1j), T,
         "residuals"),
    Case("corrtime-1d", lambda ctx: correlation_time(np.zeros(10)), V, "residuals"),
    Case("inflate-shape", lambda ctx: inflate(np.eye(3), [1.0, 1.0]), V, "alpha"),
    Case("inflate-neg", lambda ctx: inflate(np.eye(3), [-1.0, 1.0, 1.0]), V, "alpha"),
    Case("inflate-C", lambda ctx: inflate(np.eye(2), [1.0, 1.0, 1.0]), V,
         r"alpha must have shape \(2,\)"),
    Case("inflate-C-rect", lambda ctx: inflate(np.ones((2, 3)), [1.0, 1.0]), V, "C must be"),
    Case("wpn-Q", lambda ctx: world_process_noise(np.eye(2), X0), V, "Q_body"),
    Case("wpn-pose", lambda ctx: world_process_noise(I3, [0.0]), V, "pose"),
    Case("epn-shapes", lambda ctx: estimate_process_noise(F, np.zeros((5, 3)), np.zeros((5, 2))),
         V, "controls"),
    Case("epn-nan", lambda ctx: estimate_process_noise(F, np.full((6, 3), np.nan),
                                                        np.zeros((5, 2))), V, "poses"),
]
# ---------------------------------------------------------------- BeliefFilter
CASES += [
    Case("belief-measurement", lambda ctx: belief(ctx, measurement="posee"), V, "measurement"),
    Case("belief-measurement-type", lambda ctx: belief(ctx, measurement=3), V, "measurement"),
    Case("belief-localizer", lambda ctx: belief(ctx, localizer=None), T, "localizer"),
    Case("belief-unfitted", lambda ctx: belief(ctx, localizer=AppearanceLocalizer()), V,
         "fit|fitted"),
    Case("belief-motion", lambda ctx: belief(ctx, motion_model="unicycle"), T, "motion_model"),
    Case("belief-gate", lambda ctx: belief(ctx, gate_probability=1.5), V, "gate_probability"),
    Case("belief-reloc", lambda ctx: belief(ctx, relocalize_after=0), V, "relocalize_after"),
    Case("belief-reloc-f", lambda ctx: belief(ctx, relocalize_after=2.5), T, "relocalize_after"),
    Case("belief-inflate-after", lambda ctx: belief(ctx, inflate_after=0), V, "inflate_after"),
    Case("belief-inflate-factor", lambda ctx: belief(ctx, inflate_factor=0.5), V,
         "inflate_factor"),
    Case("belief-alpha-shape", lambda ctx: belief(ctx, alpha=[1.0, 1.0]), V, "alpha"),
    Case("belief-alpha-neg", lambda ctx: belief(ctx, alpha=[1.0, -1.0, 1.0]), V, "alpha"),
    Case("belief-step-before-reset", lambda ctx: belief(ctx).step(np.zeros(6), [0.0, 0.0]),
         RuntimeError, "reset"),
]
# ---------------------------------------------------------------- wrappers
CASES += [
    Case("bw-measurement", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer, measurement="x"), V,
         "measurement"),
    Case("bw-localizer", lambda ctx: BeliefWrapper(ctx.env, None), T, "localizer"),
    Case("bw-unfitted", lambda ctx: BeliefWrapper(ctx.env, AppearanceLocalizer()), V,
         "fit|fitted"),
    Case("bw-env", lambda ctx: BeliefWrapper("AppearanceNav-v0", ctx.localizer), T, "env"),
    Case("bw-gate", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer, gate_probability=2.0), V,
         "gate_probability"),
    Case("bw-reloc", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer, relocalize_after=-1), V,
         "relocalize_after"),
    Case("bw-size", lambda ctx: BeliefWrapper(gym.make("AppearanceNav-v0", image_size=(24, 24)),
                                              ctx.localizer), V, "image"),
    Case("bw-filter", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer, filter="kalman"), V,
         "filter"),
    Case("bw-filter-type", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer, filter=None), V,
         "filter"),
    Case("bw-filter-options-type", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer,
                                                             filter_options=[1]), T,
         "filter_options"),
    Case("bw-filter-options-key", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"n_particles": 10}), V, "n_particles"),
    Case("bw-pf-options-key", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter="particles", filter_options={"detect_divergence": True}),
         V, "detect_divergence"),
    Case("bw-ekf-noise", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"noise": "robust"}), V, "noise"),
    Case("bw-pf-min-mode-weight", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter="particles", filter_options={"min_mode_weight": 0.0}), V,
         "min_mode_weight"),
    Case("bw-pf-particles-0", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter="particles", filter_options={"n_particles": 0}), V,
         "n_particles"),
    Case("bw-pf-particles-neg", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter="particles", filter_options={"n_particles": -3}), V,
         "n_particles"),
    Case("bw-pf-gate-none", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter="particles", gate_probability=None), V,
         "gate_probability"),
    Case("bw-detect-type", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": "yes"}), T,
         "detect_divergence"),
    Case("bw-detect-window", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": {"window": 1}}), V,
         "window"),
    Case("bw-detect-strong-nis", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": {"strong_nis": 0.0}}), V,
         "strong_nis"),
    Case("bw-detect-sustained", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": {"sustained_steps": 0}}),
         V, "sustained_steps"),
    Case("bw-detect-doubt", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": {"doubt_nis": -1.0}}), V,
         "doubt_nis"),
    Case("bw-detect-key", lambda ctx: BeliefWrapper(
        ctx.env, ctx.localizer, filter_options={"detect_divergence": {"windw": 8}}), T,
         "detect_divergence"),
    Case("bw-localize", lambda ctx: BeliefWrapper(ctx.env, ctx.localizer).reset(
        seed=0, options={"localize": "everywhere"}), V, "localize"),
    Case("oracle-std-shape", lambda ctx: OracleWrapper(ctx.env, std=(0.1, 0.1)), V, "std"),
    Case("oracle-std-neg", lambda ctx: OracleWrapper(ctx.env, std=(0.1, -0.1, 0.1)), V, "std"),
    Case("oracle-std-nan", lambda ctx: OracleWrapper(ctx.env, std=(np.nan, 0.1, 0.1)), V, "std"),
    Case("oracle-env", lambda ctx: OracleWrapper(None), T, "env"),
    Case("dr-Q", lambda ctx: DeadReckoningWrapper(ctx.env, np.eye(2)), V, "process_noise_body"),
    Case("dr-Q-nan", lambda ctx: DeadReckoningWrapper(ctx.env, np.full((3, 3), np.nan)), V,
         "process_noise_body"),
    Case("dr-std", lambda ctx: DeadReckoningWrapper(ctx.env, I3, initial_std=(0.1, 0.1)), V,
         "initial_std"),
    Case("dr-gain", lambda ctx: DeadReckoningWrapper(ctx.env, I3, control_gain=(1.0,)), V,
         "control_gain"),
]
# ---------------------------------------------------------------- features
CASES += [
    Case("features-name", lambda ctx: make_features("sift"), V, "features"),
    Case("features-name-type", lambda ctx: make_features(None), V, "features"),
    Case("pca-n-components-0", lambda ctx: PixelPCA(n_components=0).fit(ctx.images), V,
         "n_components"),
    Case("pca-n-components-str", lambda ctx: PixelPCA(n_components="8").fit(ctx.images),
         T, "n_components"),
    Case("pca-images-float", lambda ctx: PixelPCA(n_components=2).fit(ctx.images * 1.0), V,
         "images.*uint8"),
    Case("pca-images-gray", lambda ctx: PixelPCA(n_components=2).fit(ctx.images[..., 0]), V,
         "images"),
    Case("pca-images-empty", lambda ctx: PixelPCA(n_components=2).fit(ctx.images[:0]), V,
         "images"),
    Case("pca-transform-unfitted", lambda ctx: PixelPCA().transform(ctx.images), V,
         "fit|fitted"),
    Case("pca-transform-size", lambda ctx: PixelPCA(n_components=2).fit(ctx.images).transform(
        np.zeros((2, 8, 8, 3), np.uint8)), V, "images"),
]


@pytest.mark.parametrize("case", params(CASES))
def test_bad_input_raises_a_clear_error(case, ctx):
    check(case, ctx)
