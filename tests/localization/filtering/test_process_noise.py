import numpy as np
import pytest

from envs.motion_model import UnicycleModel, wrap_angle
from localization.filtering.process_noise import (
    estimate_control_gain,
    estimate_process_noise,
    prediction_errors,
    world_process_noise,
)
from localization.geometry import body_rotation


def _drive(Q_body, n=4000, seed=0):
    """A unicycle drive whose true motion deviates from F by body-frame noise Q_body."""
    rng = np.random.default_rng(seed)
    model = UnicycleModel(0.1)
    L = np.linalg.cholesky(Q_body)
    poses = [np.array([0.0, 0.0, 3.0])]
    controls = rng.uniform([0.0, -1.5], [1.0, 1.5], (n, 2))
    for u in controls:
        p = model.predict(poses[-1], u) + body_rotation(poses[-1][2]) @ (L @ rng.standard_normal(3))
        p[2] = wrap_angle(p[2])
        poses.append(p)
    return model, np.array(poses), controls


def test_recovers_body_frame_noise_whatever_the_heading():
    Q_true = np.diag([4e-4, 1e-4, 2.5e-3])
    Q_true[0, 2] = Q_true[2, 0] = 3e-4
    model, poses, controls = _drive(Q_true)
    Q = estimate_process_noise(model, poses, controls)
    assert np.allclose(Q, Q_true, rtol=0.1, atol=2e-5)


def test_no_noise_gives_tiny_q_and_exact_errors():
    model, poses, controls = _drive(np.eye(3) * 1e-30, n=200)
    e = prediction_errors(model, poses, controls)
    assert np.abs(e).max() < 1e-9
    assert np.all(np.linalg.eigvalsh(estimate_process_noise(model, poses, controls)) > 0)


def test_world_frame_rotation():
    Q_body = np.diag([1.0, 0.01, 0.1])
    Q = world_process_noise(Q_body, [0.0, 0.0, np.pi / 2])
    # along-track (body x) noise points along world y at yaw = pi/2
    assert Q[1, 1] == pytest.approx(1.0) and Q[0, 0] == pytest.approx(0.01)


def test_episode_boundaries_are_excluded():
    model, poses, controls = _drive(np.eye(3) * 1e-8, n=300)
    poses[150:] += [50.0, 0.0, 0.0]  # a reset teleports the robot
    starts = np.zeros(300, bool)
    starts[149] = True
    Q = estimate_process_noise(model, poses, controls, episode_starts=starts)
    assert Q.max() < 1e-6


@pytest.mark.parametrize("poses,controls,match", [
    (np.zeros((5, 2)), np.zeros((4, 2)), "shape"),
    (np.zeros((5, 3)), np.zeros((5, 2)), "one more pose"),
    (np.full((5, 3), np.nan), np.zeros((4, 2)), "NaN"),
    (np.zeros((5, 3)), np.zeros((4, 2)), "at least 10"),
])
def test_bad_input(poses, controls, match):
    with pytest.raises(ValueError, match=match):
        estimate_process_noise(UnicycleModel(0.1), poses, controls)


def test_control_gain_recovers_a_slipping_robot():
    """True motion F(theta, k U) + small noise: the gains come back, and Q with them is small."""
    rng = np.random.default_rng(1)
    model = UnicycleModel(0.1)
    k_true = np.array([0.95, 0.9])
    controls = rng.uniform([0.2, -1.0], [1.0, 1.0], (600, 2))
    poses = [np.array([1.0, -2.0, 0.5])]
    for u in controls:
        p = model.predict(poses[-1], k_true * u) + rng.normal(0, [1e-4, 1e-4, 1e-4])
        p[2] = wrap_angle(p[2])
        poses.append(p)
    poses = np.array(poses)
    k = estimate_control_gain(model, poses, controls)
    assert np.allclose(k, k_true, atol=2e-3)
    Q_raw = estimate_process_noise(model, poses, controls)
    Q_cal = estimate_process_noise(model, poses, controls * k)
    assert np.trace(Q_cal) < 0.01 * np.trace(Q_raw)


def test_control_gain_of_an_unbiased_model_is_one():
    model, poses, controls = _drive(np.diag([1e-6, 1e-6, 1e-6]), n=500)
    assert np.allclose(estimate_control_gain(model, poses, controls), 1.0, atol=0.01)
