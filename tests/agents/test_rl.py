"""RL plumbing: the navigation observation wrapper, the training reward, PPO smoke test, save/load."""

import json
import tempfile
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.vec_env import DummyVecEnv

import envs  # noqa: F401  (registers the env)
from agents.observations import NavigationObservation
from agents.ppo import PPOAgent, load_policy, make_ppo, save_policy
from agents.rewards import StreetProgressReward
from agents.sources import make_pose_env
from localization.wrappers import OracleWrapper


def _nav_env(max_steps=200):
    env = gym.make("AppearanceNav-v0", scene_seed=0, motion_noise=0.05, max_episode_steps=max_steps)
    return NavigationObservation(StreetProgressReward(OracleWrapper(env)))


def test_navigation_env_passes_the_checkers():
    env = _nav_env()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # checking a wrapped env is the point here; any other warning fails the test
        warnings.filterwarnings("ignore", message=".*different from the unwrapped version")
        check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=True)
    env.close()


def test_navigation_observation_needs_a_belief_space():
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    with pytest.raises(ValueError, match="belief observation space"):
        NavigationObservation(env)
    env.close()


def test_street_progress_reward_sums_to_the_street_distance_covered():
    env = StreetProgressReward(OracleWrapper(gym.make("AppearanceNav-v0", scene_seed=0,
                                                      max_episode_steps=50)),
                               step_cost=0.0, collision_penalty=0.0, success_bonus=0.0)
    _, info = env.reset(seed=1)
    d0 = env.street_distance(info["pose"])
    total = 0.0
    for _ in range(20):
        _, r, _, _, info = env.step([0.5, 0.0])
        total += r
    assert total == pytest.approx(d0 - info["street_distance"])
    env.close()


def test_ppo_trains_saves_reloads_and_acts(tmp_path, monkeypatch):
    venv = DummyVecEnv([lambda: _nav_env(100)] * 2)
    venv.seed(0)
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    model = make_ppo(venv, seed=0, n_steps=256, batch_size=128, n_epochs=2)
    before = {k: v.clone() for k, v in model.policy.state_dict().items()}
    model.learn(2048)
    assert not list(temp.glob("SB3-*"))  # no SB3-<time> folder left behind
    assert any(not np.allclose(before[k], v) for k, v in model.policy.state_dict().items())
    path = save_policy(model, tmp_path / "policy", pose_source="oracle")
    settings = json.loads((tmp_path / "policy.json").read_text())
    assert settings["meta"]["pose_source"] == "oracle"

    policy, _ = load_policy(path)
    for k, v in model.policy.state_dict().items():
        np.testing.assert_array_equal(policy.state_dict()[k].numpy(), v.numpy())
    env = OracleWrapper(gym.make("AppearanceNav-v0", scene_seed=0, max_episode_steps=50))
    agent = PPOAgent.load(path, env.unwrapped.city)
    obs, _ = env.reset(seed=3)
    agent.reset()
    nav = agent.features(obs)
    agent.reset()
    expected, _ = model.policy.predict(nav, deterministic=True)
    action = agent.act(obs)
    np.testing.assert_allclose(action, np.clip(expected, -1, 1), atol=1e-6)
    assert env.action_space.contains(action)
    for _ in range(10):
        obs, *_ = env.step(agent.act(obs))
    venv.close()
    env.close()


def test_policy_files_are_checked(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_policy(tmp_path / "missing")
    (tmp_path / "p.pt").write_bytes(b"not torch")
    (tmp_path / "p.json").write_text(json.dumps({"format": "something else"}))
    with pytest.raises(ValueError, match="unknown policy format"):
        load_policy(tmp_path / "p")


def test_pose_sources_share_one_observation_space():
    env = make_pose_env("oracle", scene_seed=0)
    assert set(env.observation_space.spaces) == {"pose_mean", "pose_cov", "goal"}
    with pytest.raises(ValueError, match="unknown pose source"):
        make_pose_env("gps")
    with pytest.raises(ValueError, match="needs a fitted localizer"):
        make_pose_env("belief")
    env.close()


def test_lane_starts_are_on_streets_and_seeded():
    env = make_pose_env("oracle", scene_seed=0)
    city = env.unwrapped.city
    c = city.street_centers
    starts = []
    for seed in (5, 6, 5):
        _, info = env.reset(seed=seed)
        starts.append(info["pose"])
        x, y, _ = info["pose"]
        off = min(np.min(np.abs(x - c)), np.min(np.abs(y - c)))
        assert off < 0.9  # on a lane (0.2 m lateral, or on a 0.8 m turn arc)
    np.testing.assert_allclose(starts[0], starts[2], atol=1e-3)
    assert np.hypot(*(starts[0][:2] - starts[1][:2])) > 1e-3
    with pytest.raises(ValueError, match="unknown start"):
        make_pose_env("oracle", start="anywhere")
    env.close()
