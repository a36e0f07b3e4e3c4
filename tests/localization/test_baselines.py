"""Tests for localization.baselines (KNR and retrieval)."""

import warnings

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import GridSearchCV, KFold
from sklearn.neighbors import KNeighborsRegressor
from threadpoolctl import threadpool_limits

from localization.baselines import KernelRegressor, RetrievalRegressor
from localization.metrics import angular_error, rrmse
from localization.synthetic import regression_manifold


@pytest.fixture(autouse=True)
def _one_thread():
    """Tiny kNN queries with OpenMP threads on a shared, loaded 2-core box spin for ~0.1 s each."""
    with threadpool_limits(1):
        yield


def _f1(x):
    return np.sin(2 * np.pi * x[:, 0])


def _data_1d(n, seed, noise=0.1):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 1, (n, 1))
    return x, _f1(x) + noise * rng.standard_normal(n)


def test_knr_1d_accurate_and_loo_near_oracle():
    X, y = _data_1d(400, 0)
    Xt = np.linspace(0.05, 0.95, 200)[:, None]
    model = KernelRegressor(standardize=False).fit(X, y)
    pred = model.predict(Xt)
    assert pred.shape == (200,)
    assert np.sqrt(np.mean((pred - _f1(Xt)) ** 2)) < 0.05
    # oracle: the grid bandwidth minimising the true test error
    test_err = [np.mean((KernelRegressor(bandwidth=h, standardize=False).fit(X, y)
                         .predict(Xt) - _f1(Xt)) ** 2) for h in model.bandwidth_grid_]
    oracle = model.bandwidth_grid_[int(np.argmin(test_err))]
    assert 0.5 < model.bandwidth_ / oracle < 2.0
    assert model.loo_errors_.shape == model.bandwidth_grid_.shape
    assert model.bandwidth_ == model.bandwidth_grid_[np.argmin(model.loo_errors_)]


def test_knr_2d_regression_manifold():
    W, T, _ = regression_manifold(600, dim_theta=2, seed=0)
    Wt, Tt, _ = regression_manifold(200, dim_theta=2, seed=1)
    pred = KernelRegressor().fit(W, T).predict(Wt)
    assert pred.shape == (200, 2)
    assert rrmse(pred, Tt) < 0.06


def test_knn_truncated_matches_dense_for_small_bandwidth():
    W, T, _ = regression_manifold(300, dim_theta=2, seed=0)
    Wt, _, _ = regression_manifold(50, dim_theta=2, seed=1)
    dense = KernelRegressor(bandwidth=0.3).fit(W, T).predict(Wt)
    trunc = KernelRegressor(bandwidth=0.3, n_neighbors=60).fit(W, T).predict(Wt)
    np.testing.assert_allclose(trunc, dense, atol=1e-8)
    loo = KernelRegressor(n_neighbors=40).fit(W, T)
    assert loo.n_neighbors_ == 40 and np.isfinite(loo.bandwidth_)


def test_knr_far_query_no_nan_gives_nearest_target():
    X, y = _data_1d(100, 1)
    model = KernelRegressor(bandwidth=0.01, standardize=False).fit(X, y)
    far = model.predict(np.array([[1e6], [-1e6]]))
    assert np.all(np.isfinite(far))
    assert far[0] == pytest.approx(y[np.argmax(X[:, 0])])
    assert far[1] == pytest.approx(y[np.argmin(X[:, 0])])


def test_retrieval_k1_returns_training_target():
    W, T, _ = regression_manifold(200, dim_theta=3, seed=0)
    model = RetrievalRegressor(n_neighbors=1, periodic=(2,)).fit(W, T)
    pred = model.predict(W[:20])
    np.testing.assert_array_equal(pred[:, :2], T[:20, :2])
    np.testing.assert_allclose(pred[:, 2], T[:20, 2], atol=1e-12)


def test_retrieval_cv_and_accuracy():
    W, T, _ = regression_manifold(600, dim_theta=3, m=30, seed=0)
    Wt, Tt, _ = regression_manifold(200, dim_theta=3, m=30, seed=1)
    model = RetrievalRegressor(n_neighbors="cv", periodic=(2,)).fit(W, T)
    assert model.n_neighbors_ in model.cv_k_ and len(model.cv_scores_) == len(model.cv_k_)
    assert model.n_neighbors_ == model.cv_k_[int(np.argmin(model.cv_scores_))]
    pred = model.predict(Wt)
    assert rrmse(pred, Tt, columns=(0, 1)) < 0.2
    assert np.all(np.abs(pred[:, 2]) <= np.pi)


@pytest.mark.parametrize("weights", ["distance", "uniform"])
def test_retrieval_cv_scores_equal_grid_search(weights):
    """One neighbour query per fold gives GridSearchCV's scores for every k (and its k),
    also when a query repeats a training sample (zero distance; tied neighbours with
    different poses may come in either order, so the repeats carry their poses too)."""
    W, E, _ = regression_manifold(300, dim_theta=2, m=12, seed=3)
    W[150:160], E[150:160] = W[:10], E[:10]
    model = RetrievalRegressor(n_neighbors="cv", weights=weights, periodic=(), random_state=4)
    model.fit(W, E)
    Ws = (W - model.mean_) / model.scale_
    search = GridSearchCV(KNeighborsRegressor(weights=weights, algorithm="brute"),
                          {"n_neighbors": model.cv_k_}, scoring="neg_mean_squared_error",
                          cv=KFold(5, shuffle=True, random_state=4)).fit(Ws, E)
    np.testing.assert_allclose(model.cv_scores_, -search.cv_results_["mean_test_score"],
                               rtol=1e-10)
    assert model.n_neighbors_ == search.best_params_["n_neighbors"]


@pytest.mark.parametrize("make", [
    lambda: KernelRegressor(bandwidth=0.5, periodic=(1,), standardize=False),
    lambda: KernelRegressor(periodic=(1,), standardize=False),
    lambda: RetrievalRegressor(n_neighbors=6, weights="uniform", periodic=(1,)),
])
def test_periodic_targets_near_pi_not_averaged_to_zero(make):
    rng = np.random.default_rng(0)
    X = rng.uniform(0, 1, (200, 1))
    sign = np.where(np.arange(200) % 2 == 0, 1.0, -1.0)
    yaw = sign * (np.pi - 0.05)  # alternating just below +pi / just above -pi
    Y = np.column_stack([X[:, 0], yaw])
    pred = make().fit(X, Y).predict(np.array([[0.3], [0.6]]))
    err = angular_error(pred[:, 1], np.full(2, np.pi))
    assert np.all(np.abs(err) < 0.06)
    assert np.all((pred[:, 1] > -np.pi) & (pred[:, 1] <= np.pi))


@pytest.mark.parametrize("model", [
    KernelRegressor(periodic=(2,)),
    KernelRegressor(n_neighbors=15, periodic=(2,)),
    RetrievalRegressor(n_neighbors="cv", periodic=(2,)),
    RetrievalRegressor(n_neighbors=3, weights="uniform"),
])
def test_save_load_round_trip(model, tmp_path):
    W, T, _ = regression_manifold(200, dim_theta=3, seed=0)
    Wt, _, _ = regression_manifold(30, dim_theta=3, seed=1)
    model.fit(W, T)
    path = tmp_path / "model.bin"  # any name: save must not append ".npz"
    model.save(path)
    loaded = type(model).load(path)
    np.testing.assert_array_equal(loaded.predict(Wt), model.predict(Wt))
    assert loaded.get_params() == model.get_params()
    with np.load(path, allow_pickle=False) as f:
        assert set(f.files) == {"X_train", "Y_train", "settings"}
    other = RetrievalRegressor if isinstance(model, KernelRegressor) else KernelRegressor
    with pytest.raises(ValueError, match="not a"):
        other.load(path)


@pytest.mark.parametrize("cls", [KernelRegressor, RetrievalRegressor])
def test_deterministic(cls):
    W, T, _ = regression_manifold(200, dim_theta=3, seed=0)
    kw = {"n_neighbors": "cv"} if cls is RetrievalRegressor else {}
    a = cls(periodic=(2,), **kw).fit(W, T).predict(W[:40] + 0.01)
    b = cls(periodic=(2,), **kw).fit(W, T).predict(W[:40] + 0.01)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("cls", [KernelRegressor, RetrievalRegressor])
def test_bad_input(cls):
    X = np.random.default_rng(0).normal(size=(30, 3))
    Y = X[:, :2].copy()
    with pytest.raises(NotFittedError):
        cls().predict(X)
    with pytest.raises(NotFittedError):
        cls().save("unused.npz")
    with pytest.raises(ValueError, match="2-D"):
        cls().fit(X[:, 0], Y)
    with pytest.raises(ValueError, match="number"):
        cls().fit(X, Y[:20])
    bad = X.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        cls().fit(bad, Y)
    badY = Y.copy()
    badY[0, 0] = np.inf
    with pytest.raises(ValueError, match="NaN or inf"):
        cls().fit(X, badY)
    with pytest.raises(ValueError, match="periodic"):
        cls(periodic=(5,)).fit(X, Y)
    model = cls().fit(X, Y)
    with pytest.raises(ValueError, match="features"):
        model.predict(X[:, :2])
    with pytest.raises(ValueError, match="2-D"):
        model.predict(X[0])
    with pytest.raises(ValueError, match="NaN or inf"):
        model.predict(bad)


def test_bad_hyperparameters():
    X = np.random.default_rng(0).normal(size=(30, 2))
    Y = X.copy()
    with pytest.raises(ValueError, match="bandwidth"):
        KernelRegressor(bandwidth="silverman").fit(X, Y)
    with pytest.raises(ValueError, match="bandwidth"):
        KernelRegressor(bandwidth=-1.0).fit(X, Y)
    with pytest.raises(ValueError, match="bandwidth_grid"):
        KernelRegressor(bandwidth_grid=[0.1, -1]).fit(X, Y)
    with pytest.raises(ValueError, match="n_neighbors"):
        KernelRegressor(n_neighbors=0).fit(X, Y)
    with pytest.raises(ValueError, match="n_neighbors"):
        RetrievalRegressor(n_neighbors=100).fit(X, Y)
    with pytest.raises(ValueError, match="weights"):
        RetrievalRegressor(weights="gaussian").fit(X, Y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="edge of the grid"):
            KernelRegressor(bandwidth_grid=[100.0, 200.0]).fit(X, Y)
