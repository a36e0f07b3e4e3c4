"""Tests for localization.intrinsic_dim (Table I estimators)."""

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from localization.intrinsic_dim import (
    DimensionEstimate,
    _corr_dim_numpy,
    _mle_numpy,
    global_dimension,
    intrinsic_dimension_table,
    local_dimension,
    loop_cut_mask,
    pointwise_dimension,
)
from localization.synthetic import curved_3manifold, helix, swiss_roll


@pytest.fixture(autouse=True)
def _one_thread():
    with threadpool_limits(1):
        yield


CASES = {
    "helix": (lambda: helix(1000, seed=0)[0], 1),
    "swiss_roll": (lambda: swiss_roll(1000, seed=0)[0], 2),
    "curved_3manifold": (lambda: curved_3manifold(1000, seed=0)[0], 3),
}


@pytest.mark.parametrize("name", list(CASES))
def test_table_recovers_true_dimension(name):
    make, true = CASES[name]
    table = intrinsic_dimension_table(make())
    assert table["rounded"] == {"global": true, "local": true, "pointwise": true}
    for key in ("global", "local", "pointwise"):
        assert abs(table[key] - true) < 0.3
        assert isinstance(table["estimates"][key], DimensionEstimate)


def test_global_details_and_rule():
    est = global_dimension(curved_3manifold(800, seed=1)[0], d_max=5)
    rv = est.details["residual_variance"]
    assert rv.shape == (5,) and np.all(np.diff(rv[:3]) < 0)
    assert est.value == 3.0 and est.rounded == 3 and float(est) == 3.0
    assert est.details["n_graph_components"] == 1


def test_pointwise_details():
    est = pointwise_dimension(swiss_roll(800, seed=2)[0], aggregate="median")
    d = est.details
    assert d["pointwise"].shape == (800,)
    assert est.value == d["median"]
    assert 1.8 < d["mean"] < 2.3 and 1.8 < d["mle"] < 2.3


def test_numpy_fallbacks_agree_with_skdim():
    X = curved_3manifold(800, seed=3)[0]
    assert _corr_dim_numpy(X, 10, 20) == pytest.approx(local_dimension(X).value, rel=1e-6)
    np.testing.assert_allclose(_mle_numpy(X, 20),
                               pointwise_dimension(X).details["pointwise"], rtol=1e-6)


def test_duplicates_dropped_and_subsampling():
    X = helix(300, seed=0)[0]
    est = pointwise_dimension(np.vstack([X, X[:50]]))
    assert est.details["duplicates_dropped"] == 50 and np.isfinite(est.value)
    est = global_dimension(X, max_samples=200)
    assert est.details["subsampled_to"] == 200


def test_disconnected_graph_warns():
    X = helix(400, seed=0)[0]
    with pytest.warns(UserWarning, match="components"):
        est = global_dimension(np.vstack([X, X + 100.0]))
    assert est.details["n_graph_components"] == 2


@pytest.mark.parametrize("fn", [global_dimension, local_dimension, pointwise_dimension])
def test_bad_input(fn):
    X = swiss_roll(200, seed=0)[0]
    bad = X.copy()
    bad[5, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        fn(bad)
    with pytest.raises(ValueError, match="2-D"):
        fn(X[:, 0])
    with pytest.raises(ValueError, match="at least"):
        fn(X[:10])


def test_bad_parameters():
    X = swiss_roll(200, seed=0)[0]
    with pytest.raises(ValueError, match="k1"):
        local_dimension(X, k1=20, k2=10)
    with pytest.raises(ValueError, match="aggregate"):
        pointwise_dimension(X, aggregate="mode")
    with pytest.raises(ValueError, match="d_max"):
        global_dimension(X, d_max=0)


def closed_curve(n: int = 1500, ambient: int = 50, seed: int = 0) -> np.ndarray:
    """A smooth closed curve (a wobbly circle) linearly embedded in R^ambient, with noise."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 2 * np.pi, n)
    base = np.c_[np.cos(t), np.sin(t), 0.3 * np.cos(2 * t), 0.2 * np.sin(3 * t),
                 0.1 * np.cos(5 * t), 0.1 * np.sin(4 * t)]
    return base @ rng.normal(size=(6, ambient)) + 0.01 * rng.normal(size=(n, ambient))


def test_loop_cut_makes_a_closed_curve_read_one():
    X = closed_curve()
    plain = global_dimension(X)
    assert plain.value == 2.0 and "loop_cut" not in plain.details  # a circle needs R^2
    cut = global_dimension(X, cut_loop=True)
    assert cut.value == 1.0 and cut.details["loop_cut"] is True
    keep, is_loop = loop_cut_mask(X)
    assert is_loop and 0.8 * len(X) < keep.sum() < len(X)


@pytest.mark.parametrize(("make", "true"), [(lambda: helix(1000, seed=0)[0], 1),
                                            (lambda: swiss_roll(1000, seed=0)[0], 2)])
def test_loop_cut_leaves_open_manifolds_alone(make, true):
    est = global_dimension(make(), cut_loop=True)
    assert est.details["loop_cut"] is False and est.value == true


def test_loop_cut_bad_fraction():
    with pytest.raises(ValueError, match="cut_fraction"):
        loop_cut_mask(helix(100, seed=0)[0], cut_fraction=0.5)
