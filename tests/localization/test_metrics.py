"""Tests for localization.metrics."""

import numpy as np
import pytest

from localization.metrics import angular_error, angular_rmse, rmse, rrmse


def test_rrmse_perfect_and_mean_predictor():
    rng = np.random.default_rng(0)
    theta = rng.normal(size=(50, 2))
    assert rrmse(theta, theta) == 0.0
    mean_pred = np.broadcast_to(theta.mean(axis=0), theta.shape)
    assert rrmse(mean_pred, theta) == pytest.approx(1.0)


def test_rrmse_formula_and_columns():
    theta = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0], [2.0, 4.0, 0.0]])
    hat = theta + np.array([[0.1, 0.0, 0.0], [0.0, -0.2, 0.0], [0.0, 0.0, 0.0]])
    num = 0.1**2 + 0.2**2
    den = (1 + 0 + 1) + (4 + 0 + 4)
    assert rrmse(hat, theta, columns=(0, 1)) == pytest.approx(np.sqrt(num / den))
    # default excludes periodic columns
    assert rrmse(hat, theta, periodic=(2,)) == pytest.approx(np.sqrt(num / den))
    assert rrmse(hat[:, 0], theta[:, 0]) == pytest.approx(np.sqrt(0.01 / 2))


def test_rmse_wraps_periodic():
    theta = np.array([[0.0, np.pi - 0.01]])
    hat = np.array([[0.0, -np.pi + 0.01]])
    assert rmse(hat, theta, periodic=(1,)) == pytest.approx(0.02)
    assert rmse(hat, theta) == pytest.approx(2 * np.pi - 0.02)
    assert rmse(np.zeros((4, 2)), np.ones((4, 2))) == pytest.approx(np.sqrt(2))


def test_angular_error_wrapped():
    e = angular_error([np.pi - 0.1, -np.pi + 0.1, np.pi], [-np.pi + 0.1, np.pi - 0.1, -np.pi])
    np.testing.assert_allclose(e, [-0.2, 0.2, 0.0], atol=1e-12)
    e = angular_error(np.array([np.pi]), np.array([0.0]))
    assert e[0] == pytest.approx(np.pi)  # (-pi, pi]: +pi stays +pi
    assert angular_rmse([0.1, -0.1], [0.0, 0.0]) == pytest.approx(0.1)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nonfinite_raises(bad):
    a = np.zeros((3, 2))
    b = np.ones((3, 2))
    a[1, 1] = bad
    with pytest.raises(ValueError, match="NaN or inf"):
        rrmse(a, b)
    with pytest.raises(ValueError, match="NaN or inf"):
        angular_error(a, b)


def test_shape_errors():
    with pytest.raises(ValueError, match="shape mismatch"):
        rrmse(np.zeros((3, 2)), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="shape mismatch"):
        angular_error(np.zeros(3), np.zeros(4))
    with pytest.raises(ValueError, match="zero variance"):
        rrmse(np.ones((3, 1)), np.ones((3, 1)))
    with pytest.raises(ValueError, match="out of range"):
        rrmse(np.zeros((3, 2)), np.ones((3, 2)), columns=(5,))
    with pytest.raises(ValueError, match="periodic"):
        rrmse(np.zeros((3, 1)), np.arange(3.0)[:, None], periodic=(0,))
