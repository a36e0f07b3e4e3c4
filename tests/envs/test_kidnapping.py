"""KidnapWrapper: teleports at given steps or per metre driven, flags it, seeded, validated."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from scipy.stats import poisson

import envs  # noqa: F401  (registers AppearanceNav-v0)
from envs.datasets import POSE_MARGIN
from envs.kidnapping import KIDNAP_RATE_PER_METRE, PUSH_DISTANCE, PUSH_TURN, KidnapWrapper
from envs.scene import generate_city


class _Rolling(gym.Env):
    """A stand-in for AppearanceNav's pose handling: drives 1 m per step along its heading
    (no buildings, no images), so the per-metre rate can be counted over kilometres."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,))
    action_space = gym.spaces.Box(-1.0, 1.0, (2,))

    def __init__(self) -> None:
        self.city = generate_city(0)
        self.pose = np.array([0.0, 0.0, 0.0])
        self.goal = np.array([5.0, 5.0])

    def set_pose(self, pose: Any) -> None:
        self.pose = np.asarray(pose, dtype=np.float64).copy()

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pose = np.array([0.0, 0.0, 0.0])
        return np.zeros(1, np.float32), {"pose": self.pose.copy()}

    def step(self, action):
        self.pose[:2] += [np.cos(self.pose[2]), np.sin(self.pose[2])]
        return np.zeros(1, np.float32), 0.0, False, False, {"pose": self.pose.copy()}


def _kidnaps(env: gym.Env, steps: int, seed: int) -> tuple[list[int], list[np.ndarray]]:
    env.reset(seed=seed)
    at, poses = [], []
    for t in range(1, steps + 1):
        _, _, _, _, info = env.step(np.zeros(2))
        if info["kidnapped"]:
            at.append(t)
            poses.append(info["pose"])
    return at, poses


def test_kidnaps_at_the_given_steps_to_a_far_free_street_pose():
    env = gym.make("AppearanceNav-v0", scene_seed=0, image_size=(32, 32), max_episode_steps=None)
    kid = KidnapWrapper(env, at_steps=(3, 7), min_distance=5.0, seed=1)
    obs, info = kid.reset(seed=0)
    assert info["kidnapped"] is False
    city, before = env.unwrapped.city, info["pose"]
    flags = []
    for _ in range(8):
        prev_image = obs["image"]
        obs, _, _, _, info = kid.step(np.array([0.2, 0.0]))
        flags.append(info["kidnapped"])
        if info["kidnapped"]:
            assert np.hypot(*(info["pose"][:2] - before[:2])) >= 5.0 - 0.05  # one step driven
            assert city.is_free(info["pose"][0], info["pose"][1], POSE_MARGIN - 0.05)
            assert not np.array_equal(obs["image"], prev_image)
        before = info["pose"]
    assert flags == [False, False, True, False, False, False, True, False]
    assert kid.kidnaps == 2
    env.close()


def test_a_push_shoves_the_robot_sideways_to_a_free_pose():
    env = gym.make("AppearanceNav-v0", scene_seed=0, image_size=(32, 32), max_episode_steps=None,
                   motion_noise=0.0)
    kid = KidnapWrapper(env, at_steps=(2,), push=PUSH_DISTANCE, seed=1)
    city, low, high = env.unwrapped.city, *PUSH_DISTANCE
    sides = []
    for seed in range(6):
        _, info = kid.reset(seed=seed)
        _, _, _, _, info = kid.step(np.zeros(2))
        before = info["pose"]
        _, _, _, _, info = kid.step(np.zeros(2))  # pushed, then a step at rest
        assert info["kidnapped"]
        d, yaw = info["pose"][:2] - before[:2], before[2]
        along = d @ [np.cos(yaw), np.sin(yaw)]
        side = d @ [-np.sin(yaw), np.cos(yaw)]
        if np.hypot(*d) > 0:  # stays put only where no free pose was drawn
            assert abs(along) < 0.02 and low - 0.02 <= abs(side) <= high + 0.02
            assert abs(np.angle(np.exp(1j * (info["pose"][2] - yaw)))) <= PUSH_TURN + 0.02
            assert city.is_free(info["pose"][0], info["pose"][1], POSE_MARGIN - 0.05)
            sides.append(np.sign(side))
    assert len(sides) >= 4 and len(set(sides)) == 2  # both sides
    env.close()


def test_rate_per_metre_is_a_poisson_process_in_the_distance_driven():
    """20 runs of 2000 m at 0.005 kidnaps per metre: 200 expected; the total must lie in
    the 99.9 % Poisson interval (and each run's count is seeded: same seed, same steps)."""
    total = 0
    for seed in range(20):
        kid = KidnapWrapper(_Rolling(), rate_per_metre=KIDNAP_RATE_PER_METRE, min_distance=0.0)
        at, _poses = _kidnaps(kid, 2000, seed)
        assert _kidnaps(kid, 2000, seed)[0] == at
        total += len(at)
    lo, hi = poisson.ppf([0.0005, 0.9995], 200)
    assert lo <= total <= hi, total


def test_no_kidnap_without_steps_or_rate_and_seeded_poses():
    kid = KidnapWrapper(_Rolling())
    assert _kidnaps(kid, 300, 0)[0] == []
    a = KidnapWrapper(_Rolling(), at_steps=(2, 5, 9))
    b = KidnapWrapper(_Rolling(), at_steps=(2, 5, 9))
    pa, pb = _kidnaps(a, 10, 4)[1], _kidnaps(b, 10, 4)[1]
    np.testing.assert_array_equal(pa, pb)
    assert not np.array_equal(pa, _kidnaps(b, 10, 5)[1])


def test_reward_does_not_count_the_teleport():
    kid = KidnapWrapper(_Rolling(), at_steps=(1,), min_distance=3.0, seed=0)
    kid.reset(seed=0)
    _, reward, _, _, _ = kid.step(np.zeros(2))
    base = kid.env.unwrapped
    assert reward == pytest.approx(0.0 + np.hypot(*(base.pose[:2] - [np.cos(base.pose[2]),
                                                                    np.sin(base.pose[2])]
                                                   - base.goal))
                                   - np.hypot(*(np.zeros(2) - base.goal)))


@pytest.mark.parametrize("kwargs, error, match", [
    ({"at_steps": (0,)}, ValueError, "at_steps"),
    ({"at_steps": (2.5,)}, ValueError, "at_steps"),
    ({"rate_per_metre": -0.1}, ValueError, "rate_per_metre"),
    ({"rate_per_metre": float("nan")}, ValueError, "rate_per_metre"),
    ({"min_distance": -1.0}, ValueError, "min_distance"),
    ({"seed": "a"}, TypeError, "seed"),
    ({"lanes": "rivers"}, ValueError, "lanes"),
    ({"push": (1.0, 0.5)}, ValueError, "push"),
    ({"push": 1.0}, ValueError, "push"),
    ({"push": (-1.0, 1.0)}, ValueError, "push"),
])
def test_bad_arguments_raise_clear_errors(kwargs, error, match):
    with pytest.raises(error, match=match):
        KidnapWrapper(_Rolling(), **kwargs)


def test_needs_an_appearance_nav_env():
    with pytest.raises(TypeError, match="AppearanceNav"):
        KidnapWrapper(gym.make("CartPole-v1"))
    kid = KidnapWrapper(_Rolling(), at_steps=(1,))
    with pytest.raises(RuntimeError, match="reset"):
        kid.step(np.zeros(2))
