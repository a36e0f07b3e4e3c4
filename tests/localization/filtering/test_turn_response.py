"""The robot's turn response: what it really turns at for a command, and the belief that
predicts with it (``BeliefFilter(turn_response=...)``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 (registers the env)
from envs.motion_model import UnicycleModel
from localization.filtering import BeliefFilter
from localization.filtering.turn_response import (
    ROBOT_TURN_RESPONSE,
    TurnResponse,
    measure_turn_response,
    turn_response_for,
)


def test_the_packaged_table_is_the_robot_s_physics_in_another_city():
    """Measured afresh on city 0 (the table comes from city 53): on the spot the robot
    turns well below the command, and the table says so everywhere within 0.06 rad/s."""
    env = gym.make("AppearanceNav-v0", image_size=(16, 16))
    _, info = env.reset(seed=0)
    speeds, rates = (0.0, 0.3, 0.6), (0.0, 0.4, 1.0)
    measured = measure_turn_response(env, info["pose"], speeds=speeds, turn_rates=rates)
    table = [[ROBOT_TURN_RESPONSE([v, w]) for w in rates] for v in speeds]
    np.testing.assert_allclose(measured.yaw_rates, table, atol=0.06)
    assert measured.yaw_rates[0, 1] < 0.75 * 0.4  # the dead zone on the spot


def test_a_measurement_needs_room():
    env = gym.make("AppearanceNav-v0", image_size=(16, 16))
    _, info = env.reset(seed=1)  # faces a building about a metre ahead
    with pytest.raises(ValueError, match="touched the city from pose"):
        measure_turn_response(env, info["pose"], speeds=(0.6,), turn_rates=(0.0, 1.0))


def test_the_response_is_odd_in_w_bilinear_and_held_at_the_edges():
    r = TurnResponse([0.0, 1.0], [0.0, 1.0], [[0.0, 0.5], [0.0, 0.9]])
    assert r([0.5, 0.5]) == pytest.approx(0.5 * (0.25 + 0.45))
    assert r([0.5, -0.5]) == pytest.approx(-r([0.5, 0.5]))
    assert r([2.0, 3.0]) == pytest.approx(0.9) and r([-1.0, -1.0]) == pytest.approx(-0.5)
    assert r([0.7, 0.0]) == 0.0


@pytest.mark.parametrize("args, match", [
    (([0.0], [0.0, 1.0], [[0.0, 1.0]]), "speeds"),
    (([1.0, 0.0], [0.0, 1.0], [[0.0, 1.0], [0.0, 1.0]]), "speeds"),
    (([0.0, 1.0], [0.5, 1.0], [[0.0, 1.0], [0.0, 1.0]]), "turn_rates"),
    (([0.0, 1.0], [0.0, 1.0], [[0.0, 1.0]]), "yaw_rates"),
    (([0.0, 1.0], [0.0, 1.0], [[0.0, np.nan], [0.0, 1.0]]), "yaw_rates"),
])
def test_bad_tables_are_named(args, match):
    with pytest.raises(ValueError, match=match):
        TurnResponse(*args)


def test_a_bad_command_or_option_is_named():
    with pytest.raises(ValueError, match="u"):
        ROBOT_TURN_RESPONSE([0.1, 0.2, 0.3])
    assert turn_response_for(True) is ROBOT_TURN_RESPONSE
    assert turn_response_for(False) is None and turn_response_for(None) is None
    with pytest.raises(TypeError, match="turn_response"):
        turn_response_for("robot")


class _NoMaps:
    """A localizer whose every image is out of its maps' domain: steps only predict."""

    control_gain_ = np.ones(2)

    def consistency(self, measurement):
        return np.ones(3)

    def measurement_model(self, measurement, alpha=None, **options):
        return None

    def process_noise(self, pose, alpha=None):
        return 1e-6 * np.eye(3)

    def initial_belief(self, w):
        return np.full(3, np.nan), np.eye(3)

    def prior(self):
        return np.zeros(3), np.eye(3)

    def measure(self, w, measurement):
        return np.full(3, np.nan)


@pytest.mark.parametrize("option, expected", [(False, 0.5), (True, None)])
def test_the_belief_turns_as_the_robot_does(option, expected):
    """Ten steps turning on the spot at 0.5 rad/s: the commanded 0.5 rad without
    ``turn_response``, the robot's 10 x 0.1 x r(0, 0.5) with it."""
    belief = BeliefFilter(_NoMaps(), UnicycleModel(0.1), turn_response=option)
    belief.reset(np.zeros(3), x0=np.zeros(3), P0=0.01 * np.eye(3))
    for _ in range(10):
        belief.step(np.array([0.0, 0.5]), np.zeros(3))
    turned = expected if expected is not None else ROBOT_TURN_RESPONSE([0.0, 0.5])
    assert belief.x[2] == pytest.approx(turned, abs=1e-9)
    assert ROBOT_TURN_RESPONSE([0.0, 0.5]) < 0.4  # so the two differ by over 0.1 rad
    np.testing.assert_allclose(belief.x[:2], 0.0, atol=1e-12)


def test_a_bad_turn_response_is_named():
    with pytest.raises(TypeError, match="turn_response"):
        BeliefFilter(_NoMaps(), UnicycleModel(0.1), turn_response=0.5)
