"""BeliefWrapper, OracleWrapper, DeadReckoningWrapper: spaces, checkers, vector envs,
the initial belief, gating of corrupted images, clear errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from sklearn.exceptions import NotFittedError
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from localization.filtering.ekf import PoseEKF, PoseMeasurement
from localization.geometry import cov_to_triu, position_std, triu_to_cov
from localization.localizer import MEASUREMENTS, AppearanceLocalizer
from localization.wrappers import (
    BeliefWrapper,
    DeadReckoningWrapper,
    OracleWrapper,
)

from .conftest import make_env

KEYS = {"pose_mean", "pose_cov", "goal"}


def wrappers(localizer):
    return {
        "belief": lambda env: BeliefWrapper(env, localizer),
        "oracle": lambda env: OracleWrapper(env),
        "dead_reckoning": lambda env: DeadReckoningWrapper(
            env, localizer.process_noise_body_, control_gain=localizer.control_gain_),
    }


def start_pose(env) -> np.ndarray:
    from envs.datasets import PurePursuit

    return PurePursuit(env.unwrapped.city.route()).start_pose(100)


def test_triu_round_trip():
    A = np.random.default_rng(0).normal(size=(3, 3))
    P = A @ A.T
    v = cov_to_triu(P)
    assert v.shape == (6,) and v.dtype == np.float32
    assert np.allclose(triu_to_cov(v), P, rtol=1e-6)
    with pytest.raises(ValueError, match="6"):
        triu_to_cov(np.zeros(5))


def test_position_std_is_the_widest_position_axis():
    """0.3 m along a rotated axis, 0.1 m across; the heading's variance does not count."""
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s], [s, c]])
    P = np.diag([0.0, 0.0, 4.0])
    P[:2, :2] = R @ np.diag([0.09, 0.01]) @ R.T
    assert position_std(P) == pytest.approx(0.3)
    assert position_std(np.zeros((3, 3))) == 0.0


@pytest.mark.filterwarnings("ignore::UserWarning")  # env_checker: wrapped env, infinite Box
@pytest.mark.parametrize("kind", ["belief", "oracle", "dead_reckoning"])
def test_same_space_and_checkers(localizer, kind):
    env = wrappers(localizer)[kind](make_env(max_episode_steps=20))
    assert set(env.observation_space.spaces) == KEYS
    assert env.observation_space["pose_mean"].shape == (3,)
    assert env.observation_space["pose_cov"].shape == (6,)
    check_env(env.unwrapped)  # the base env stays valid
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=False)
    obs, info = env.reset(seed=0, options={"pose": start_pose(env)})
    assert env.observation_space.contains(obs)
    assert np.isfinite(info["nees"])
    env.close()


@pytest.mark.parametrize("measurement", MEASUREMENTS)
def test_each_measurement_model_runs(localizer, measurement):
    env = BeliefWrapper(make_env(), localizer, measurement=measurement, keep_image=True)
    obs, info = env.reset(seed=0, options={"pose": start_pose(env)})
    assert set(obs) == KEYS | {"image"}
    for _ in range(15):
        obs, _, _, _, info = env.step([0.5, 0.0])
        assert info["measurement_status"] in ("accepted", "gated", "out_of_domain", "relocalized",
                                              "reverted")
        assert np.isfinite(info["nees"]) and np.all(np.isfinite(obs["pose_mean"]))
        P = triu_to_cov(obs["pose_cov"])
        assert np.all(np.linalg.eigvalsh(P) > 0)
    assert info["nis_dof"] == (localizer.noise_["features"].shape[0]
                               if measurement == "features" else 3)
    env.close()


def test_initial_belief_is_psi_star_not_the_truth(localizer):
    env = BeliefWrapper(make_env(), localizer)
    obs, info = env.reset(seed=0, options={"pose": start_pose(env)})
    psi = localizer.predict(env.unwrapped.render_camera()[None])[0]
    assert np.allclose(obs["pose_mean"], psi, atol=1e-5)
    assert not np.allclose(obs["pose_mean"], info["pose"], atol=1e-3)
    env.close()


def test_the_spec_refers_to_the_localizer_without_copying_it(localizer):
    base = make_env()
    free = base.unwrapped.city.free_mask  # a bound method: a deep copy would copy the city
    options = {"heading_check": 0.05, "free_space": free}
    env = BeliefWrapper(base, localizer, filter_options=options)
    kwargs = env.spec.additional_wrappers[-1].kwargs
    assert kwargs["localizer"] is localizer  # a 60 m map is a gigabyte: never deep-copied
    assert kwargs["filter_options"] == options and kwargs["filter_options"] is not options
    assert kwargs["filter_options"]["free_space"].__self__ is free.__self__
    outer = gym.wrappers.RecordEpisodeStatistics(env)  # an outer spec deep-copies the inner
    assert outer.spec.additional_wrappers[-2].kwargs["localizer"] is localizer
    env.close()


def test_oracle_and_dead_reckoning():
    Q = np.diag([1e-4, 1e-5, 1e-3])
    oracle = OracleWrapper(make_env())
    dr = DeadReckoningWrapper(make_env(), Q)
    for env in (oracle, dr):
        obs, info = env.reset(seed=1, options={"pose": start_pose(env)})
        assert np.allclose(obs["pose_mean"], info["pose"], atol=1e-5)
    covs = []
    for _ in range(30):
        obs_o, _, _, _, info_o = oracle.step([0.6, 0.1])
        obs_d, _, _, _, info_d = dr.step([0.6, 0.1])
        covs.append(np.trace(triu_to_cov(obs_d["pose_cov"])))
    assert np.allclose(obs_o["pose_mean"], info_o["pose"], atol=1e-5)
    assert np.all(np.diff(covs) > 0)  # dead-reckoning uncertainty grows
    assert np.hypot(*(obs_d["pose_mean"][:2] - info_d["pose"][:2])) < 1.0
    with pytest.raises(ValueError, match="std"):
        OracleWrapper(make_env(), std=(0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="process_noise_body"):
        DeadReckoningWrapper(make_env(), np.eye(2))


def test_sync_vector_env(localizer):
    venv = gym.vector.SyncVectorEnv(
        [lambda: BeliefWrapper(make_env(max_episode_steps=8), localizer) for _ in range(2)])
    obs, _ = venv.reset(seed=[0, 1])
    assert obs["pose_mean"].shape == (2, 3) and obs["pose_cov"].shape == (2, 6)
    for _ in range(10):  # crosses the time limit: autoreset re-initialises the belief
        obs, _, _, _, _ = venv.step(np.tile([0.4, 0.1], (2, 1)))
        assert np.all(np.isfinite(obs["pose_mean"]))
    venv.close()


class CorruptAt(gym.ObservationWrapper):
    """Replace the image at given steps by black or noise (a camera glitch)."""

    def __init__(self, env, steps, kind):
        super().__init__(env)
        self.steps, self.kind, self.t = set(steps), kind, 0

    def reset(self, **kw):
        self.t = 0
        return super().reset(**kw)

    def step(self, action):
        self.t += 1
        return super().step(action)

    def observation(self, obs):
        if self.t in self.steps:
            img = obs["image"]
            obs = dict(obs)
            obs["image"] = (np.zeros_like(img) if self.kind == "black" else
                            np.random.default_rng(self.t).integers(0, 256, img.shape,
                                                                   dtype=np.uint8))
        return obs


@pytest.mark.parametrize("kind", ["black", "noise"])
@pytest.mark.parametrize("measurement", ["representation", "pose", "features"])
def test_corrupted_image_is_rejected_without_a_jump(localizer, kind, measurement):
    env = BeliefWrapper(CorruptAt(make_env(), [12], kind), localizer, measurement=measurement)
    obs, _ = env.reset(seed=0, options={"pose": start_pose(env)})
    u = np.array([0.5, 0.0])
    for t in range(1, 15):
        before = env.belief.x
        obs, _, _, _, info = env.step(u)
        if t == 12:
            assert info["measurement_status"] in ("gated", "out_of_domain")
            prior = env.unwrapped.motion_model.predict(before, env.localizer.control_gain_ * u)
            assert np.allclose(obs["pose_mean"], prior, atol=1e-4)  # prediction only
    env.close()


def test_unfitted_and_incompatible_localizers(localizer):
    with pytest.raises(NotFittedError):
        BeliefWrapper(make_env(), AppearanceLocalizer())
    bigger = gym.make("AppearanceNav-v0", scene_seed=0, image_size=(48, 48))
    with pytest.raises(ValueError, match="32, 32"):
        BeliefWrapper(bigger, localizer)
    fisheye = gym.make("AppearanceNav-v0", scene_seed=0, image_size=(32, 32), camera="fisheye")
    with pytest.raises(ValueError, match="camera"):
        BeliefWrapper(fisheye, localizer)
    with pytest.raises(ValueError, match="measurement"):
        BeliefWrapper(make_env(), localizer, measurement="lidar")
    with pytest.raises(gym.error.ResetNeeded):
        BeliefWrapper(make_env(), localizer).step([0.1, 0.0])
    for e in (bigger, fisheye):
        e.close()


def test_nan_measurement_is_a_clear_error(localizer):
    ekf = PoseEKF(make_env().unwrapped.motion_model, np.eye(3) * 1e-4, np.zeros(3), np.eye(3))
    with pytest.raises(ValueError, match="NaN"):
        ekf.update(np.array([0.0, np.nan, 0.0]), PoseMeasurement(np.eye(3)))
    with pytest.raises(ValueError, match="NaN"):
        localizer.measure(np.full(localizer.noise_["features"].shape[0], np.nan), "pose")
