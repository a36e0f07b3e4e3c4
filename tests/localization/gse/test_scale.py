"""Tests of the scalable GSE path (algorithm="approximate") and of incremental GSE
(partial_fit); docs/method.md §17-§18."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.utils.estimator_checks import parametrize_with_checks

from localization.gse import GrassmannStiefelEigenmaps, GSERegressor
from localization.gse.graph import knn_graph
from localization.gse.neighbors import APPROXIMATE_MIN_N, HNSWIndex, use_approximate
from localization.metrics import angular_rmse, rrmse
from localization.synthetic import FeatureMap, regression_manifold

PHI = FeatureMap(3, m=24, seed=1234, periodic=(2,))


def _poses(n: int, x0: float, x1: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(x0, x1, n), rng.uniform(0, 1, n),
                            rng.uniform(-np.pi, np.pi, n)])


@pytest.fixture(scope="module")
def pose3():
    """3-DoF synthetic regression manifold: 2400 training, 600 test samples."""
    W, T, _ = regression_manifold(2400, dim_theta=3, m=24, seed=0, map_seed=1234)
    Wt, Tt, _ = regression_manifold(600, dim_theta=3, m=24, seed=1, map_seed=1234)
    return W, T, Wt, Tt


def _scores(model: GSERegressor, Wt: np.ndarray, Tt: np.ndarray) -> tuple[float, float]:
    P = model.predict(Wt)
    assert np.isfinite(P).all()
    return rrmse(P, Tt, columns=(0, 1)), angular_rmse(P[:, 2], Tt[:, 2])


# ---------------------------------------------------------------- scalable path
def test_algorithm_auto_switches_by_n():
    assert not use_approximate("auto", APPROXIMATE_MIN_N - 1)
    assert use_approximate("auto", APPROXIMATE_MIN_N)
    assert use_approximate("approximate", 10) and not use_approximate("exact", 10 ** 6)
    with pytest.raises(ValueError, match="algorithm"):
        GSERegressor(algorithm="fast").fit(*regression_manifold(100, seed=0)[:2])


def test_hnsw_index_finds_the_exact_neighbours_deterministically():
    X = np.random.default_rng(0).normal(size=(3000, 16))
    Xq = np.random.default_rng(1).normal(size=(200, 16))
    d2, ind = HNSWIndex(X).query(Xq, 10)
    true = np.argsort(((Xq[:, None] - X[None]) ** 2).sum(-1), axis=1)[:, :10]
    recall = np.mean([len(set(a) & set(b)) / 10 for a, b in zip(ind, true, strict=True)])
    assert recall >= 0.98
    np.testing.assert_allclose(d2, ((Xq[:, None] - X[ind]) ** 2).sum(-1), rtol=1e-12)
    assert np.all(np.diff(d2, axis=1) >= 0)
    d2b, indb = HNSWIndex(X).query(Xq, 10)  # a second build: the same graph
    assert np.array_equal(ind, indb) and np.array_equal(d2, d2b)
    far = Xq[:20] + 50.0  # far from the sample: the guard answers by brute force, exactly
    _, indf = HNSWIndex(X).query(far, 10)
    true = np.argsort(((far[:, None] - X[None]) ** 2).sum(-1), axis=1)[:, :10]
    np.testing.assert_array_equal(indf, true)


@pytest.fixture(scope="module")
def approx3(pose3):
    W, T, _, _ = pose3
    return GSERegressor(periodic=(2,), algorithm="approximate").fit(W, T)


def test_approximate_path_agrees_with_the_exact_path(pose3, approx3):
    """n q = 7200 > 3000: the alignment runs AMG-preconditioned LOBPCG from the landmark
    frames, the embedding AMG-preconditioned CG, the neighbours come from HNSW."""
    W, T, Wt, Tt = pose3
    exact = GSERegressor(periodic=(2,), algorithm="exact").fit(W, T)
    assert exact.algorithm_ == "exact" and approx3.algorithm_ == "approximate"
    (pe, he), (pa, ha) = _scores(exact, Wt, Tt), _scores(approx3, Wt, Tt)
    assert pa <= 1.05 * pe and ha <= 1.05 * he
    # the same neighbourhood graph (up to a few missed links) and the same fitted maps
    same = np.mean(np.sort(exact.gse_.neighbors_, 1) == np.sort(approx3.gse_.neighbors_, 1))
    assert same > 0.99
    diff = np.abs(wrap_diff(exact.predict(Wt), approx3.predict(Wt)))
    assert np.median(diff[:, :2]) < 0.1 * pe * Tt[:, :2].std()
    lam = approx3.gse_.alignment_eigenvalues_
    np.testing.assert_allclose(lam[:3], exact.gse_.alignment_eigenvalues_[:3], rtol=1e-3)
    assert np.all(approx3.gse_.frame_condition_ < 10)


def wrap_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a - b
    d[:, 2] = np.angle(np.exp(1j * d[:, 2]))
    return d


def test_approximate_path_same_seed_same_result(pose3, approx3):
    W, T, Wt, _ = pose3
    again = GSERegressor(periodic=(2,), algorithm="approximate").fit(W, T)
    np.testing.assert_array_equal(again.embedding_, approx3.embedding_)
    np.testing.assert_array_equal(again.predict(Wt), approx3.predict(Wt))


def test_approximate_model_survives_save_and_load(pose3, approx3, tmp_path):
    Wt = pose3[2]
    approx3.save(tmp_path / "m.npz")
    back = GSERegressor.load(tmp_path / "m.npz")
    assert back.algorithm_ == "approximate"
    np.testing.assert_array_equal(back.predict(Wt), approx3.predict(Wt))


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@parametrize_with_checks([GSERegressor(n_neighbors=7, algorithm="approximate"),
                          GrassmannStiefelEigenmaps(n_components=1, n_neighbors=5,
                                                    algorithm="approximate")],
                         expected_failed_checks=lambda e: e._expected_failed_checks(),
                         xfail_strict=True)
def test_sklearn_estimator_checks_approximate(estimator, check):
    check(estimator)


# ---------------------------------------------------------------- incremental GSE
@pytest.fixture(scope="module")
def grown():
    """A model of x in [0, 1] grown by a strip x in [1, 1.1] (a new street), and the
    refit on the union."""
    T0, T1 = _poses(2000, 0.0, 1.0, 0), _poses(200, 1.0, 1.1, 1)
    base = GSERegressor(periodic=(2,), algorithm="exact").fit(PHI(T0), T0)
    inc = GSERegressor(periodic=(2,), algorithm="exact").fit(PHI(T0), T0)
    inc.partial_fit(PHI(T1), T1)
    union = np.vstack([T0, T1])
    ref = GSERegressor(periodic=(2,), algorithm="exact").fit(PHI(union), union)
    return base, inc, ref, T0, T1


def test_partial_fit_matches_a_refit_on_the_union(grown):
    base, inc, ref, _, _ = grown
    Tt = _poses(600, 0.0, 1.1, 7)
    Ts = _poses(300, 1.0, 1.1, 8)  # only the new strip
    for T in (Tt, Ts):
        (pi, hi), (pr, hr) = _scores(inc, PHI(T), T), _scores(ref, PHI(T), T)
        assert pi <= 1.05 * pr and hi <= 1.05 * hr
    # the new strip was outside the base model: it was worse there (or out of domain)
    base.set_params(out_of_domain="nan")
    P = base.predict(PHI(Ts))
    ok = np.isfinite(P).all(1)
    assert (~ok).any() or rrmse(P, Ts, columns=(0, 1)) > 1.2 * _scores(inc, PHI(Ts), Ts)[0]


def test_partial_fit_builds_the_knn_graph_of_the_union(grown):
    """Exact path: the updated neighbour lists are those of the union; only the new rows
    and the old rows near them changed."""
    _, inc, _, T0, T1 = grown
    g = inc.gse_
    dist, ind = knn_graph(g.Z_, g.n_neighbors)
    np.testing.assert_array_equal(np.sort(g.neighbors_, 1), np.sort(ind, 1))
    np.testing.assert_allclose(g.neighbor_distances_, dist, rtol=1e-10)
    rows = inc.partial_fit_rows_
    assert set(range(len(T0), len(T0) + len(T1))) <= set(rows.tolist())
    assert len(rows) < 0.5 * (len(T0) + len(T1))
    assert np.median(T0[rows[rows < len(T0)], 0]) > 0.85  # the old rows that changed: near x = 1
    assert inc.embedding_.shape == (2200, 3) and inc.Gr_.shape[0] == 2200
    assert np.isfinite(inc.GR_).all() and np.isfinite(inc.theta_radius_).all()


def test_partial_fit_same_data_same_result(grown):
    _, inc, _, T0, T1 = grown
    again = GSERegressor(periodic=(2,), algorithm="exact").fit(PHI(T0), T0)
    again.partial_fit(PHI(T1), T1)
    np.testing.assert_array_equal(again.embedding_, inc.embedding_)
    Tq = _poses(50, 0.0, 1.1, 9)
    np.testing.assert_array_equal(again.predict(PHI(Tq)), inc.predict(PHI(Tq)))


def test_partial_fit_on_the_approximate_path_and_after_load(tmp_path):
    T0, T1 = _poses(1500, 0.0, 1.0, 0), _poses(150, 1.0, 1.1, 1)
    m = GSERegressor(periodic=(2,), algorithm="approximate").fit(PHI(T0), T0)
    m.save(tmp_path / "m.npz")
    loaded = GSERegressor.load(tmp_path / "m.npz")
    m.partial_fit(PHI(T1), T1)
    loaded.partial_fit(PHI(T1), T1)
    Tq = _poses(200, 0.0, 1.1, 5)
    np.testing.assert_array_equal(m.predict(PHI(Tq)), loaded.predict(PHI(Tq)))
    union = np.vstack([T0, T1])
    ref = GSERegressor(periodic=(2,), algorithm="approximate").fit(PHI(union), union)
    assert _scores(m, PHI(Tq), Tq)[0] <= 1.05 * _scores(ref, PHI(Tq), Tq)[0]
    m.save(tmp_path / "grown.npz")  # a grown model saves and loads like a fitted one
    np.testing.assert_array_equal(GSERegressor.load(tmp_path / "grown.npz").predict(PHI(Tq)),
                                  m.predict(PHI(Tq)))


def test_partial_fit_bad_inputs(grown):
    _, inc, _, _, T1 = grown
    W1 = PHI(T1[:5])
    with pytest.raises(NotFittedError, match="'fit' before 'partial_fit'"):
        GSERegressor().partial_fit(W1, T1[:5])
    with pytest.raises(NotFittedError, match="'fit' before 'partial_fit'"):
        GrassmannStiefelEigenmaps().partial_fit(W1)
    n_before = len(inc.theta_)
    with pytest.raises(ValueError, match="W: X has 10 features.*24 features"):
        inc.partial_fit(W1[:, :10], T1[:5])
    bad = W1.copy()
    bad[2, 3] = np.nan
    with pytest.raises(ValueError, match="W contains NaN"):
        inc.partial_fit(bad, T1[:5])
    badT = T1[:5].copy()
    badT[1, 0] = np.inf
    with pytest.raises(ValueError, match="y contains NaN or inf"):
        inc.partial_fit(W1, badT)
    with pytest.raises(ValueError, match="y has shape.*pose layout"):
        inc.partial_fit(W1, T1[:5, :2])
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        inc.partial_fit(W1, T1[:4])
    with pytest.raises(ValueError, match="duplicate"):
        inc.partial_fit(PHI(inc.theta_[:1]), inc.theta_[:1])  # a training sample again
    assert len(inc.theta_) == n_before  # a rejected update leaves the model as it was


def test_kneighbors_are_the_training_samples_nearest_in_feature_space(pose3, approx3):
    """The retrieval the particle belief proposes from: exact on the exact path, the HNSW
    index with exact distances on the approximate one."""
    from sklearn.neighbors import NearestNeighbors

    W, T, Wt, _ = pose3
    exact = GSERegressor(periodic=(2,), algorithm="exact").fit(W, T)
    Ws = (W - exact.w_mean_) / exact.w_scale_
    d_true, ind_true = NearestNeighbors(n_neighbors=10).fit(Ws).kneighbors(
        (Wt[:50] - exact.w_mean_) / exact.w_scale_)
    for model, recall in ((exact, 1.0), (approx3, 0.98)):
        d, ind = model.kneighbors(Wt[:50], 10)
        assert d.shape == ind.shape == (50, 10) and np.all(np.diff(d, axis=1) >= 0)
        assert np.mean([len(set(a) & set(b)) / 10 for a, b in zip(ind, ind_true)]) >= recall
        np.testing.assert_allclose(d, np.sqrt(((Wt[:50, None] - W[ind]) ** 2).sum(-1))
                                   / model.w_scale_, rtol=1e-9)
    np.testing.assert_allclose(exact.kneighbors(Wt[:50], 10)[0], d_true, rtol=1e-9)
    assert exact.kneighbors(Wt[:1], 10 ** 6)[1].shape == (1, len(W))
    with pytest.raises(ValueError, match="n_neighbors"):
        exact.kneighbors(Wt[:1], 0)
    with pytest.raises(ValueError, match="W"):
        exact.kneighbors(Wt[:1, :3], 5)
