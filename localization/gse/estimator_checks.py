"""scikit-learn's estimator checks that cannot apply to the GSE estimators, with reasons.

``parametrize_with_checks(..., expected_failed_checks=...)`` / ``check_estimator`` take
these dictionaries (``{check name: reason}``); the estimators return them from
``_expected_failed_checks()``. Some depend on the hyperparameters: the checks fit on
10-40 samples, often with 2 features, or on two separated blobs.
"""

from __future__ import annotations

from typing import Any

_IRIS = ("the check fits on iris, which has duplicate rows: GSE rejects duplicate samples "
         "(a zero-distance neighbour leaves the local tangent undefined)")

#: Training sets of scikit-learn's estimator checks that are small or have 2 features.
_EMBEDDING_SIZES = {"check_estimators_nan_inf": 10, "check_n_features_in_after_fitting": 15}
_CHECK_TWO_FEATURES = ("check_estimators_overwrite_params", "check_estimators_fit_returns_self",
                       "check_readonly_memmap_input", "check_fit_idempotent",
                       "check_fit_check_is_fitted", "check_n_features_in")
_BLOB_CHECKS = ("check_pipeline_consistency", "check_estimators_pickle",
                "check_transformer_data_not_an_array", "check_transformer_general",
                "check_transformer_preserve_dtypes")


#: partial_fit adds samples to a fitted model (docs/method.md §18); these checks call it on
#: an unfitted estimator, or pass it the samples of the fit again.
_PARTIAL_FIT = {
    "check_n_features_in_after_fitting": (
        "the check calls partial_fit on an unfitted estimator: incremental GSE updates a "
        "fitted embedding locally and needs fit first (it raises NotFittedError)"),
    "check_fit_score_takes_y": (
        "the check passes the samples of fit to partial_fit again: GSE rejects duplicate "
        "samples (a zero-distance neighbour leaves the local tangent undefined)"),
}


def embedding_expected_failed_checks(model: Any) -> dict[str, str]:
    """The scikit-learn estimator checks ``model`` cannot pass, each with its reason."""
    k, q = model.n_neighbors, model.n_components
    out = {"check_positive_only_tag_during_fit": _IRIS, **_PARTIAL_FIT}
    if k < 15:
        out |= dict.fromkeys(_BLOB_CHECKS, (
            f"the check's data are two separated blobs of 15 samples: with n_neighbors={k} "
            "the neighbour graph is disconnected, and GSE embeds one connected manifold"))
    else:
        out |= dict.fromkeys(_BLOB_CHECKS[2:4], (
            "the check's data are two tight blobs joined by a few kNN links: the out-of-sample "
            "map (transform) reproduces their least-squares embedding (fit_transform) only to "
            "~0.05, not to the check's 0.01"))
    if q >= 2:
        out |= dict.fromkeys(_CHECK_TWO_FEATURES, (
            f"n_components={q} needs more than {q} features and the check's data have 2"))
    for check, n in _EMBEDDING_SIZES.items():
        if n <= k:
            out[check] = (f"n_neighbors={k} needs more than {k} samples and the check fits on "
                          f"{n}; n_neighbors <= {n - 1} passes it")
    return out



#: Training-set sizes of scikit-learn's estimator checks that use fewer than 22 samples.
_REGRESSOR_SIZES = {"check_estimators_nan_inf": 10, "check_fit2d_1feature": 10,
                "check_regressors_no_decision_function": 10, "check_regressor_multioutput": 11,
                "check_n_features_in_after_fitting": 15, "check_dont_overwrite_parameters": 20,
                "check_estimators_dtypes": 20,
                "check_f_contiguous_array_estimator": 20, "check_dict_unchanged": 20,
                "check_methods_sample_order_invariance": 20,
                "check_methods_subset_invariance": 20, "check_fit2d_predict1d": 20,
                "check_estimators_overwrite_params": 21, "check_estimators_fit_returns_self": 21,
                "check_readonly_memmap_input": 21}


def regressor_expected_failed_checks(model: Any) -> dict[str, str]:
    """The scikit-learn estimator checks ``model`` cannot pass, each with its reason."""
    k = model.n_neighbors
    out = {"check_positive_only_tag_during_fit": _IRIS, **_PARTIAL_FIT,
           "check_estimators_partial_fit_n_features": _PARTIAL_FIT[
               "check_n_features_in_after_fitting"]}
    if k < 15:
        out |= dict.fromkeys(("check_pipeline_consistency", "check_estimators_pickle"), (
            "the check's data are two separated blobs of 15 samples with a constant target "
            f"on each: with n_neighbors={k} no neighbourhood sees the pose vary (so "
            "theta_scale='auto' is 0) and the neighbour graph is disconnected"))
    for check, n in _REGRESSOR_SIZES.items():
        if n <= k + 1:
            out[check] = (f"n_neighbors={k} needs more than {k + 1} samples and the check fits "
                          f"on {n}; n_neighbors <= {n - 2} passes it")
    return out
