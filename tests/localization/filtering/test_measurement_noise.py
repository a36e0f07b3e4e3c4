"""Noise-model maths: robust covariance, body frame, correlation time, consistency inflation."""

import numpy as np
import pytest

from localization.filtering.measurement_noise import (
    body_errors,
    consistency_inflation,
    correlation_time,
    inflate,
    robust_covariance,
)
from localization.geometry import body_to_world, to_body


def test_robust_covariance_ignores_gross_errors():
    rng = np.random.default_rng(0)
    C = np.array([[0.04, 0.01, 0.0], [0.01, 0.02, 0.0], [0.0, 0.0, 1e-4]])
    e = rng.multivariate_normal(np.zeros(3), C, 3000)
    e[:150] += rng.normal(0, 5.0, (150, 3))  # 5 % aliasing: metres off
    e[150:160] = np.nan
    R = robust_covariance(e)
    assert np.allclose(R, C, rtol=0.15, atol=2e-4)
    finite = e[np.isfinite(e).all(axis=1)]
    assert np.trace(np.cov(finite.T)) > 20 * np.trace(C)  # the plain covariance is ruined
    with pytest.raises(ValueError, match="at least"):
        robust_covariance(e[:10])


def test_body_frame_round_trip():
    yaw = np.array([0.0, np.pi / 2, -2.0])
    e_world = np.array([[1.0, 0.0, 0.1], [1.0, 0.0, 0.0], [0.3, -0.2, 3.5]])
    e_body = to_body(e_world, yaw)
    assert np.allclose(e_body[1], [0.0, -1.0, 0.0])  # facing +y, +x is to the right
    assert np.isclose(e_body[2, 2], 3.5 - 2 * np.pi)
    C = np.diag([1.0, 0.01, 0.1])
    W = body_to_world(C, np.pi / 2)
    assert np.isclose(W[1, 1], 1.0) and np.isclose(W[0, 0], 0.01)
    means = e_world + [0, 0, 0]
    poses = np.zeros((3, 3))
    poses[:, 2] = yaw
    e, P = body_errors(means + poses * [1, 1, 0], np.tile(W, (3, 1, 1)), poses)
    assert e.shape == (3, 3) and P.shape == (3, 3, 3)
    assert np.allclose(P[1], C)


def test_correlation_time_of_ar1():
    """AR(1) with coefficient phi: tau = (1 + phi) / (1 - phi); white noise: 1."""
    rng = np.random.default_rng(3)
    n, phi = 40000, 0.8
    x = np.zeros((n, 2))
    eps = rng.standard_normal((n, 2))
    x[:, 1] = eps[:, 1]
    for t in range(1, n):
        x[t, 0] = phi * x[t - 1, 0] + eps[t, 0]
    tau = correlation_time(x, block=100)
    assert tau[0] == pytest.approx((1 + phi) / (1 - phi), rel=0.2)
    assert tau[1] == pytest.approx(1.0, abs=0.2)
    with pytest.raises(ValueError, match="block"):
        correlation_time(x[:50], block=50)


def test_consistency_inflation_scales_an_over_confident_filter():
    """A 'filter' whose errors are 3x (along) and 1x its claimed sd gets alpha ~ (9, 1, 1)."""
    rng = np.random.default_rng(4)
    n = 4000
    poses = np.column_stack([rng.normal(size=(n, 2)), rng.uniform(-np.pi, np.pi, n)])
    sd = np.array([0.1, 0.05, 0.01])
    e_body = rng.normal(size=(n, 3)) * sd * [3.0, 1.0, 0.5]

    def run(alpha):
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        means = poses + np.column_stack([c * e_body[:, 0] - s * e_body[:, 1],
                                         s * e_body[:, 0] + c * e_body[:, 1], e_body[:, 2]])
        covs = np.array([body_to_world(inflate(np.diag(sd ** 2), alpha), y) for y in poses[:, 2]])
        return means, covs

    alpha = consistency_inflation(run, poses, burn_in=0)  # the clipped mean: 3-4 iterations
    assert alpha[0] == pytest.approx(9.0, rel=0.1)
    assert alpha[1] == pytest.approx(1.0, rel=0.1)
    assert alpha[2] == 1.0  # never deflated

    # 1 % gross errors (15 sd across track, 0.75 m: an aliased stretch, not lost) barely move
    # alpha; the plain mean of e^2 / P would ask for ~3x across track
    e_body[::100, 1] = 15.0 * sd[1]
    robust = consistency_inflation(run, poses, burn_in=0)
    assert robust[1] < 1.5
    assert robust[0] == pytest.approx(9.0, rel=0.15)
