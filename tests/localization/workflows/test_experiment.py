"""The Table II harness: hyper-parameters by CV on the training split, failures recorded."""

from __future__ import annotations

import numpy as np
import pytest

from localization.synthetic import route_manifold
from localization.workflows.experiment import evaluate_methods, position_errors, whitened


def test_route_harness_chooses_on_training_data_and_gse_wins():
    W, T, _, _ = route_manifold(400, seed=0, lateral=0.001)
    Wt, Tt, _, _ = route_manifold(150, seed=1, lateral=0.001)
    res, preds, models = evaluate_methods(W, T, Wt, Tt, q=1, cv=2,
                                          gse_grid={"n_neighbors": [12]},
                                          feature_dims=(8, 30))
    by = {r.method: r for r in res}
    assert set(by) == {"gse", "knr", "knn"} and set(preds) == set(models)
    for r in res:
        assert r.params["n_features"] in (8, 30) and r.heading_rmse is None
        assert {row["n_features"] for row in r.cv} == {8, 30}
        assert np.isclose(r.rrmse, position_errors(preds[r.method], Tt)["rrmse"])
    assert by["gse"].params["loop_cut"]
    assert by["gse"].rrmse < 0.7 * by["knr"].rrmse  # measured 0.0032 vs 0.0112


def test_a_failing_method_is_recorded_not_raised():
    W, T, _, _ = route_manifold(200, seed=0)
    W2, T2 = np.vstack([W, W + 50.0]), np.vstack([T, T + 0.002])  # two feature clusters
    res, preds, _ = evaluate_methods(W2, T2, W2[:20], T2[:20], q=1, cv=2,
                                     gse_grid={"n_neighbors": [10]}, methods=("gse", "knn"))
    gse = res[0]
    assert np.isnan(gse.rrmse) and "connected components" in gse.params["error"]
    assert "gse" not in preds and np.isfinite(res[1].rrmse)


def test_variants_are_chosen_by_cv_and_their_test_features_used():
    W, T, _, _ = route_manifold(300, seed=0, lateral=0.001)
    Wt, Tt, _, _ = route_manifold(100, seed=1, lateral=0.001)
    rng = np.random.default_rng(0)
    noise = (rng.normal(size=W.shape) * 50.0, rng.normal(size=Wt.shape) * 50.0)
    res, preds, _ = evaluate_methods(W, T, Wt, Tt, q=1, cv=2, methods=("knn",),
                                     variants={"noise": (W + noise[0], Wt + noise[1]),
                                               "whitened": whitened(W, Wt)})
    knn = res[0]
    assert knn.params["variant"] in ("plain", "whitened")  # the noisy copy loses the CV
    assert {row["variant"] for row in knn.cv} == {"plain", "noise", "whitened"}
    assert np.isclose(knn.rrmse, position_errors(preds["knn"], Tt)["rrmse"])
    with pytest.raises(ValueError, match="variants\\['bad'\\] must have the shapes"):
        evaluate_methods(W, T, Wt, Tt, q=1, methods=("knn",), variants={"bad": (W[:, :3], Wt)})


def test_whitened_scales_by_the_training_columns():
    rng = np.random.default_rng(0)
    W = rng.normal(size=(50, 3)) * [1.0, 10.0, 0.0]
    a, b = whitened(W, W[:5])
    np.testing.assert_allclose(a[:, :2].std(axis=0), 1.0)
    np.testing.assert_array_equal(a[:, 2], 0.0)  # a constant column is left alone
    np.testing.assert_array_equal(b, a[:5])


def test_verified_gse_reuses_the_model_and_switches_only_to_training_poses():
    """``verify``: a "gse_verified" row from the same GSE model (no second fit); its
    predictions are psi*'s except where a retrieved training pose replaced them, and an
    unreachable margin switches nothing; a negative ``verify`` is named."""
    W, T, _, _ = route_manifold(300, seed=0, lateral=0.001)
    Wt, Tt, _, _ = route_manifold(100, seed=1, lateral=0.001)
    common = {"q": 1, "cv": 2, "gse_grid": {"n_neighbors": [12]}, "methods": ("gse",)}
    # margin 1: any candidate that explains w better replaces psi* (measured: 3 of 100)
    res, preds, models = evaluate_methods(W, T, Wt, Tt, verify=10, verify_margin=1.0, **common)
    by = {r.method: r for r in res}
    assert set(by) == set(preds) == {"gse", "gse_verified"}
    assert models["gse_verified"] is models["gse"]
    v = by["gse_verified"].params
    assert (v["verify"], v["verify_margin"], v["n_features"]) == (10, 1.0,
                                                                 by["gse"].params["n_features"])
    moved = np.any(preds["gse_verified"] != preds["gse"], axis=1)
    assert moved.sum() == v["switched"] > 0
    train = {tuple(p) for p in T}
    assert all(tuple(p) in train for p in preds["gse_verified"][moved])
    assert np.isclose(by["gse_verified"].rrmse,
                      position_errors(preds["gse_verified"], Tt)["rrmse"])
    res, preds, _ = evaluate_methods(W, T, Wt, Tt, verify=10, verify_margin=1e12, **common)
    np.testing.assert_array_equal(preds["gse_verified"], preds["gse"])
    with pytest.raises(ValueError, match="verify"):
        evaluate_methods(W, T, Wt, Tt, verify=-1, **common)
