"""The unicycle motion model F: predictions, angle wrapping, Jacobians vs finite differences."""

import numpy as np
import pytest

from envs.motion_model import UnicycleModel, wrap_angle


def numeric_jacobian(f, x, eps=1e-4):
    # eps not smaller: near w = 0 the exact-arc branch divides by w and cancels digits
    x = np.asarray(x, dtype=np.float64)
    cols = []
    for i in range(len(x)):
        d = np.zeros_like(x)
        d[i] = eps
        diff = f(x + d) - f(x - d)
        diff[2] = wrap_angle(diff[2])
        cols.append(diff / (2 * eps))
    return np.stack(cols, axis=1)


def test_wrap_angle_range():
    a = np.linspace(-20, 20, 1001)
    w = wrap_angle(a)
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    assert np.allclose(np.sin(w), np.sin(a)) and np.allclose(np.cos(w), np.cos(a))
    assert wrap_angle(-np.pi) == pytest.approx(np.pi)


def test_straight_and_turning():
    F = UnicycleModel(0.1)
    assert np.allclose(F.predict([0, 0, 0], [1.0, 0.0]), [0.1, 0, 0])
    # a quarter circle of radius 1: v = 1, w = 1 over pi/2 s
    G = UnicycleModel(np.pi / 2)
    assert np.allclose(G.predict([0, 0, 0], [1.0, 1.0]), [1.0, 1.0, np.pi / 2])


@pytest.mark.parametrize("u", [[0.7, 0.9], [0.5, 0.0], [-0.3, 1e-7], [0.0, -1.2], [1.0, -0.4]])
def test_jacobians_match_finite_differences(u):
    F = UnicycleModel(0.1)
    rng = np.random.default_rng(0)
    for _ in range(5):
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi + 0.1, np.pi - 0.1)])
        num_x = numeric_jacobian(lambda p: F.predict(p, u), pose)
        num_u = numeric_jacobian(lambda c, p=pose: F.predict(p, c), np.asarray(u, dtype=np.float64))
        assert np.allclose(F.jacobian_pose(pose, u), num_x, atol=1e-6)
        assert np.allclose(F.jacobian_control(pose, u), num_u, atol=1e-6)


def test_bad_inputs():
    F = UnicycleModel(0.1)
    with pytest.raises(ValueError, match="shape"):
        F.predict([0, 0], [1, 0])
    with pytest.raises(ValueError, match="NaN"):
        F.predict([0, 0, np.nan], [1, 0])
    with pytest.raises(ValueError):
        UnicycleModel(0.0)
