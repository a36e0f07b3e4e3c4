"""Tests for localization.intrinsic_dim (Table I estimators)."""

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components
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
from localization.intrinsic_dim_geodesic import (
    geodesic_correlation_dimension,
    mutual_knn_mst_graph,
)
from localization.synthetic import curved_3manifold, helix, route_manifold, swiss_roll


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


# --- geodesic correlation dimension (localization.intrinsic_dim_geodesic) -------------------


def rough_curve(n: int = 1500, ambient: int = 50, seed: int = 0) -> np.ndarray:
    """A random walk in R^ambient: a curve whose Euclidean distances grow like the square
    root of the arc length (as images along a route do), so Euclidean estimators read ~2."""
    return np.cumsum(np.random.default_rng(seed).normal(size=(n, ambient)), axis=0)


def torus(n: int, d: int, seed: int = 0, ambient: int = 30) -> np.ndarray:
    """A flat d-torus (no boundary), orthonormally embedded in R^ambient."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 2.0 * np.pi, (n, d))
    basis = np.linalg.qr(rng.normal(size=(ambient, 2 * d)))[0]
    return np.hstack([np.cos(t), np.sin(t)]) @ basis.T


@pytest.mark.parametrize(("make", "true"), [
    (closed_curve, 1),  # a loop reads 1 without a cut
    (rough_curve, 1),
    (lambda: route_manifold(1500, seed=0)[0], 1),  # 1.5 laps of a closed route
    (lambda: swiss_roll(1500, seed=0)[0], 2),
    (lambda: torus(1500, 2), 2),
])
def test_geodesic_correlation_dimension_recovers_true_dimension(make, true):
    est = geodesic_correlation_dimension(make())
    assert est.rounded == true and abs(est.value - true) < 0.3
    assert est.method == "geodesic_correlation_dimension"
    d = est.details
    assert d["radii"].shape == d["correlation"].shape and np.all(np.diff(d["radii"]) > 0)
    assert 0.004 < d["correlation"][0] < d["correlation"][-1] < 0.06


def test_geodesic_correlation_dimension_reads_low_in_three_dimensions():
    """Documented bias: multi-hop graph paths zigzag, so in 3-D the slope reads ~2.5."""
    three = geodesic_correlation_dimension(torus(2000, 3)).value
    assert 2.3 < three < 3.2
    assert three > geodesic_correlation_dimension(torus(2000, 2)).value + 0.4


def test_geodesic_beats_euclidean_on_a_rough_curve():
    X = rough_curve()
    assert local_dimension(X).value > 1.6  # Euclidean correlation dimension is fooled
    assert geodesic_correlation_dimension(X).value < 1.3


def test_mutual_knn_mst_graph_is_connected_and_symmetric():
    X = np.vstack([helix(300, seed=0)[0], helix(300, seed=1)[0] + 50.0])  # two far pieces
    D = np.linalg.norm(X[:, None] - X[None], axis=2)
    G = mutual_knn_mst_graph(D, 5)
    assert abs(G - G.T).max() == 0
    assert connected_components(G, directed=False)[0] == 1  # the tree joins the pieces
    assert (G > 40).nnz == 2  # by one edge only (both directions)


def test_geodesic_bad_parameters():
    X = swiss_roll(200, seed=0)[0]
    with pytest.raises(ValueError, match="pair_range"):
        geodesic_correlation_dimension(X, pair_range=(0.1, 0.05))
    with pytest.raises(ValueError, match="n_scales"):
        geodesic_correlation_dimension(X, n_scales=1)
    with pytest.raises(ValueError, match="n_neighbors"):
        geodesic_correlation_dimension(X, n_neighbors=0)
    with pytest.raises(ValueError, match="at least"):
        geodesic_correlation_dimension(X[:5])
    with pytest.raises(ValueError, match="n_neighbors"):
        mutual_knn_mst_graph(np.zeros((3, 3)), 3)
