"""log_sum_exp and normalise_log_weights against scipy, and at the edges where weights underflow."""

import numpy as np
import pytest
from scipy.special import logsumexp

from localization.filtering.log_weights import log_sum_exp, normalise_log_weights


@pytest.mark.parametrize("scale", [1.0, 1e3, 1e6])
def test_log_sum_exp_matches_scipy(scale: float) -> None:
    a = np.random.default_rng(0).normal(size=700) * scale
    assert log_sum_exp(a) == pytest.approx(float(logsumexp(a)), rel=1e-12, abs=1e-12)


def test_log_sum_exp_does_not_underflow() -> None:
    a = np.array([-2000.0, -2001.0])  # exp underflows to 0 without the shift
    assert log_sum_exp(a) == pytest.approx(-2000.0 + np.log1p(np.exp(-1.0)))


def test_log_sum_exp_edges() -> None:
    assert log_sum_exp(np.array([])) == -np.inf
    assert log_sum_exp(np.full(3, -np.inf)) == -np.inf
    assert np.isnan(log_sum_exp(np.array([0.0, np.nan])))
    assert log_sum_exp(np.array([-np.inf, 0.0])) == 0.0


def test_normalised_weights_sum_to_one() -> None:
    log_w = np.random.default_rng(1).normal(size=50) - 5000.0
    w = np.exp(normalise_log_weights(log_w))
    assert w.sum() == pytest.approx(1.0)
    assert np.allclose(w, np.exp(log_w - logsumexp(log_w)))
