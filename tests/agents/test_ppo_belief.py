"""PPO on the particle belief (issue 17): the status and bumper observations, the
active-localization reward term, and a short training that saves, reloads and acts identically.

A tiny city-0 localizer (700 route-lane images at 32 x 32, 16 PCA features, noise from a
240-step drive) is enough: the test checks the plumbing, not the navigation.
"""

from __future__ import annotations

import json
import warnings

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

import envs  # noqa: F401  (registers the env)
from agents.observations import (
    BUMPER_DECAY,
    NavigationFeatures,
    NavigationObservation,
    status_one_hot,
)
from agents.ppo import PPOAgent, load_policy, make_ppo, save_policy
from agents.rewards import StreetProgressReward, position_entropy
from agents.sources import make_pose_env
from envs.datasets import collect_dataset, drive_route
from localization.filtering.divergence import BELIEF_STATUSES
from localization.localizer import AppearanceLocalizer

SIZE = (32, 32)
PF = {"n_particles": 50}


@pytest.fixture(scope="module")
def localizer() -> AppearanceLocalizer:
    env = gym.make("AppearanceNav-v0", scene_seed=0, image_size=SIZE, motion_noise=0.05)
    images, poses = collect_dataset(env, 700, "lanes", seed=0, progress=False, lanes="route")
    loc = AppearanceLocalizer(features_params={"n_components": 16}, noise_folds=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # GSE's eigen-gap notes on city data
        loc.fit(images, poses, camera="perspective")
    loc.fit_noise(env.unwrapped.motion_model, *drive_route(env, 240, seed=5, progress=False))
    env.close()
    return loc


def _particle_env(loc: AppearanceLocalizer, penalty: float = 0.0) -> gym.Env:
    env = make_pose_env("belief", loc, image_size=SIZE, motion_noise=0.05, start="random",
                        max_episode_steps=60, kidnap_at=(30,), filter="particles",
                        filter_options=PF)
    return NavigationObservation(StreetProgressReward(env, uncertainty_penalty=penalty),
                                 status=True, bumper=True)


def test_status_observation_is_the_info_status_one_hot(localizer):
    env = _particle_env(localizer)
    obs, info = env.reset(seed=4)
    assert env.observation_space.contains(obs)
    np.testing.assert_array_equal(obs["status"], status_one_hot(info["belief_status"]))
    for _ in range(5):
        obs, _, _, _, info = env.step(np.array([0.5, 0.0], np.float32))
        np.testing.assert_array_equal(obs["status"], status_one_hot(info["belief_status"]))
    assert status_one_hot(None)[BELIEF_STATUSES.index("tracking")] == 1.0
    with pytest.raises(ValueError, match="status must be one of"):
        status_one_hot("confused")
    env.close()


def test_bumper_observation_remembers_where_and_how_long_ago_the_robot_was_touched():
    env = make_pose_env("oracle", max_episode_steps=40)
    features = NavigationFeatures(env.unwrapped.city, bumper=True)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(features(obs)["bumper"], [0.0, 0.0, 0.0])  # reset: none
    hit = {"collision": True, "collision_bearing": np.pi / 2}  # touched on the left
    np.testing.assert_allclose(features(obs, None, hit)["bumper"], [1.0, 0.0, 1.0], atol=1e-7)
    quiet = {"collision": False, "collision_bearing": None}
    np.testing.assert_allclose(features(obs, None, quiet)["bumper"], [BUMPER_DECAY, 0.0, 1.0],
                               atol=1e-7)
    np.testing.assert_allclose(features(obs, None, quiet)["bumper"],
                               [BUMPER_DECAY ** 2, 0.0, 1.0], atol=1e-7)
    push = {"collision": True, "collision_with": ("traffic",), "collision_bearing": None}
    np.testing.assert_array_equal(features(obs, None, push)["bumper"], [1.0, 0.0, 0.0])
    features.reset()
    np.testing.assert_array_equal(features(obs, None, quiet)["bumper"], [0.0, 0.0, 0.0])
    assert "bumper" not in NavigationFeatures(env.unwrapped.city)(obs)
    wrapped = NavigationObservation(env, bumper=True)  # reads the step's info
    obs, _ = wrapped.reset(seed=0)
    assert wrapped.observation_space.contains(obs) and obs["bumper"][0] == 0.0
    touched = 0.0
    for _ in range(3):
        obs, _, _, _, info = wrapped.step(np.array([0.5, 0.0], np.float32))
        touched = 1.0 if info["collision"] else touched * BUMPER_DECAY
        assert obs["bumper"][0] == pytest.approx(touched)
    env.close()


def test_entropy_penalty_charges_only_uncertainty_above_the_reference():
    assert position_entropy([0.01, 0.0, 0.0, 0.01, 0.0, 0.01]) == pytest.approx(np.log(0.01))
    assert position_entropy([0.0] * 6) == -np.inf
    with pytest.raises(ValueError, match="pose_cov must be"):
        position_entropy([1.0, 0.0, 1.0])
    plain = gym.make("AppearanceNav-v0", scene_seed=0)
    with pytest.raises(ValueError, match="needs belief observations with pose_cov"):
        StreetProgressReward(plain, uncertainty_penalty=0.1)
    with pytest.raises(ValueError, match="uncertainty_penalty"):
        StreetProgressReward(plain, uncertainty_penalty=-1.0)
    plain.close()


def test_kidnap_step_earns_no_progress():
    env = StreetProgressReward(make_pose_env("oracle", max_episode_steps=40, kidnap_at=(5,)),
                               step_cost=0.0, collision_penalty=0.0, success_bonus=0.0)
    env.reset(seed=2)
    for _ in range(6):
        _, reward, _, _, info = env.step(np.array([0.5, 0.0], np.float32))
        if info["kidnapped"]:
            assert reward == 0.0
    env.close()


def test_short_ppo_on_the_particle_belief_saves_reloads_and_acts_identically(localizer,
                                                                             tmp_path):
    venv = DummyVecEnv([lambda: _particle_env(localizer, penalty=0.01)] * 2)
    venv.seed(0)
    model = make_ppo(venv, seed=0, n_steps=32, batch_size=32, n_epochs=2)
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.learn(64)  # one rollout of 2 x 32 steps (a kidnap at step 30), one update
    assert any(not np.allclose(before[k], v) for k, v in model.policy.state_dict().items())
    path = save_policy(model, tmp_path / "policy", status=True, bumper=True,
                       pose_source="belief")
    assert json.loads((tmp_path / "policy.json").read_text())["bumper"] is True
    policy, settings = load_policy(path)
    assert settings["status"] is True and settings["bumper"] is True
    for k, v in model.policy.state_dict().items():
        np.testing.assert_array_equal(policy.state_dict()[k].numpy(), v.numpy())

    env = make_pose_env("belief", localizer, image_size=SIZE, motion_noise=0.05,
                        start="random", max_episode_steps=40, kidnap_at=(5,),
                        filter="particles", filter_options=PF)
    agent = PPOAgent.load(path, env.unwrapped.city)
    reference = NavigationFeatures(env.unwrapped.city, status=True, bumper=True)  # training's
    obs, info = env.reset(seed=7)
    agent.reset()
    for _ in range(8):
        expected, _ = model.policy.predict(reference(obs, info["belief_status"], info),
                                           deterministic=True)
        action = agent.act(obs, info)
        np.testing.assert_allclose(action, np.clip(expected, -1, 1), atol=1e-6)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    venv.close()
    env.close()


def test_policies_saved_before_the_status_and_bumper_load_without_them(tmp_path):
    venv = DummyVecEnv([lambda: NavigationObservation(StreetProgressReward(
        make_pose_env("oracle", max_episode_steps=20)))])
    model = make_ppo(venv, seed=0, n_steps=32, batch_size=32, n_epochs=1)
    save_policy(model, tmp_path / "old")
    settings = json.loads((tmp_path / "old.json").read_text())
    del settings["status"], settings["bumper"]  # as written before either existed
    (tmp_path / "old.json").write_text(json.dumps(settings))
    _, loaded = load_policy(tmp_path / "old")
    assert loaded["status"] is False and loaded["bumper"] is False
    settings["status"] = "yes"
    (tmp_path / "old.json").write_text(json.dumps(settings))
    with pytest.raises(ValueError, match="status must be true or false"):
        load_policy(tmp_path / "old")
    venv.close()
