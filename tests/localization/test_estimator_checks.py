"""scikit-learn's own estimator checks on our estimators (``parametrize_with_checks``).

Each estimator lists the checks that cannot apply to it, with the reason, in its
``_expected_failed_checks()``; they run as strict xfails, so a listed check that starts
to pass fails here and the list must shrink. GSE is checked twice: with settings for the
checks' tiny data sets (10-21 samples, as scikit-learn tests TSNE with a small perplexity)
and with its defaults.
"""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.utils.estimator_checks import parametrize_with_checks

from localization.baselines import KernelRegressor, RetrievalRegressor
from localization.gse import GrassmannStiefelEigenmaps, GSERegressor
from localization.synthetic import regression_manifold

ESTIMATORS = [
    KernelRegressor(),
    RetrievalRegressor(),
    GSERegressor(n_neighbors=7),
    GSERegressor(),
    GrassmannStiefelEigenmaps(n_components=1, n_neighbors=5),
    GrassmannStiefelEigenmaps(),
]


def _curve(n: int = 150, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Features (n, 4) on a smooth curve parametrised by a 1-D pose t (n,)."""
    t = np.sort(np.random.default_rng(seed).uniform(0.0, 1.0, n))
    return np.column_stack([np.cos(2 * t), np.sin(2 * t), t ** 2, np.sin(5 * t)]), t


def _expected_failures(estimator: object) -> dict[str, str]:
    return getattr(estimator, "_expected_failed_checks", dict)()


# The checks' toy data (random points, class labels as targets) trip GSE's diagnostics
# (weak alignment eigen-gap, piecewise-constant poses): RuntimeWarnings that
# pyproject.toml turns into errors for our own data sets.
@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@parametrize_with_checks(ESTIMATORS, expected_failed_checks=_expected_failures,
                         xfail_strict=True)
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)


@pytest.mark.parametrize("estimator", ESTIMATORS[:3], ids=lambda e: type(e).__name__)
def test_1d_target_gives_1d_predictions(estimator):
    W, y = _curve()
    one = clone(estimator).fit(W, y).predict(W[:20])
    two = clone(estimator).fit(W, y[:, None]).predict(W[:20])
    assert one.shape == (20,) and two.shape == (20, 1)
    np.testing.assert_allclose(one, two[:, 0], rtol=0, atol=1e-12)


def test_gse_1d_target_survives_save_and_load(tmp_path):
    W, y = _curve()
    model = GSERegressor(n_neighbors=10).fit(W, y)
    model.save(tmp_path / "m.npz")
    loaded = GSERegressor.load(tmp_path / "m.npz")
    assert loaded.n_features_in_ == W.shape[1]
    np.testing.assert_array_equal(loaded.predict(W[:5]), model.predict(W[:5]))


def test_gse_n_components_larger_than_pose_dimension_names_it():
    W, T, _ = regression_manifold(150, dim_theta=2, seed=0)
    with pytest.raises(ValueError, match=r"n_components=3 must be at most .* \(2\)"):
        GSERegressor(n_components=3, n_neighbors=10).fit(W, T)


@pytest.mark.parametrize(("estimator", "param"), [
    (GSERegressor(n_neighbors=0), "n_neighbors"),
    (GSERegressor(out_of_domain="warn"), "out_of_domain"),
    (GSERegressor(loop_cut="yes"), "loop_cut"),
    (GSERegressor(agreement=-1.0), "agreement"),
    (GSERegressor(theta_scale="median"), "theta_scale"),
    (GrassmannStiefelEigenmaps(eigen_solver="arpack"), "eigen_solver"),
    (GrassmannStiefelEigenmaps(bandwidth=0.0), "bandwidth"),
    (KernelRegressor(standardize="yes"), "standardize"),
    (RetrievalRegressor(cv=1), "cv"),
    (RetrievalRegressor(algorithm="annoy"), "algorithm"),
], ids=lambda v: v if isinstance(v, str) else type(v).__name__)
def test_bad_hyperparameters_name_the_parameter(estimator, param):
    W, T, _ = regression_manifold(60, dim_theta=2, seed=0)
    with pytest.raises(ValueError, match=f"'{param}' parameter of {type(estimator).__name__}"):
        estimator.fit(W, T)


@pytest.mark.parametrize("estimator", ESTIMATORS[:3], ids=lambda e: type(e).__name__)
def test_wrong_feature_count_names_the_argument(estimator):
    W, T, _ = regression_manifold(60, dim_theta=2, seed=0)
    model = clone(estimator).fit(W, T)
    with pytest.raises(ValueError, match=r"^(W|X): X has 3 features, but \w+ is expecting"):
        model.predict(W[:, :3])
