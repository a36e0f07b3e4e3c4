"""appearance-nav's localization toolkit: images -> features -> GSE regression -> pose belief.

The public names, grouped by layer (imports flow one way, top to bottom)::

    geometry      wrap_angle, pose_residual, body_to_world, ...   (numpy only)
    recorded      load_recorded, read_tum, write_tum   (image folders, TUM poses; numpy + Pillow)
    features      PixelPCA, EfficientNetFeatures, SmallCNNFeatures, make_features
    gse           GrassmannStiefelEigenmaps, GSERegressor, jacobian_regression
    baselines     KernelRegressor, RetrievalRegressor (+ metrics, model_selection, ...)
    filtering     PoseEKF, BeliefFilter, ParticleBelief, noise models
    localizer     AppearanceLocalizer, city_info, OtherCityError
    districts     DistrictLocalizer (one localizer per district of a large city)
    experiences   ExperienceLocalizer (one localizer per look: day, dusk, night, ...)
    wrappers      BeliefWrapper, OracleWrapper, DeadReckoningWrapper
    workflows     fit_city_localizer, track_route, ... (import the simulator)

Every name loads on first use (like ``gymnasium.wrappers``): ``import localization`` imports
neither MuJoCo nor torch, and PixelPCA never needs torch.
"""

from __future__ import annotations

from localization._lazy import lazy_names

__version__ = "0.1.0"

_LAZY = {
    # geometry
    "wrap_angle": "geometry", "pose_residual": "geometry", "body_to_world": "geometry",
    "to_body": "geometry", "cov_to_triu": "geometry", "triu_to_cov": "geometry",
    # recorded data (image folders + TUM pose files, our .npz)
    "load_recorded": "recorded", "read_tum": "recorded", "write_tum": "recorded",
    # features
    "PixelPCA": "features", "EfficientNetFeatures": "features",
    "SmallCNNFeatures": "features", "FeatureExtractor": "features",
    "make_features": "features", "features_from_state": "features",
    # GSE and the other regressors
    "GrassmannStiefelEigenmaps": "gse", "GSERegressor": "gse",
    "jacobian_regression": "gse",
    "KernelRegressor": "baselines", "RetrievalRegressor": "baselines",
    "grid_search": "model_selection", "select_n_neighbors": "model_selection",
    "rrmse": "metrics", "rmse": "metrics", "angular_rmse": "metrics",
    "angular_error": "metrics",
    "intrinsic_dimension_table": "intrinsic_dim", "global_dimension": "intrinsic_dim",
    "geodesic_correlation_dimension": "intrinsic_dim_geodesic",
    # filtering
    "PoseEKF": "filtering", "PoseMeasurement": "filtering",
    "FunctionMeasurement": "filtering", "OutOfDomainError": "filtering",
    "BeliefFilter": "filtering", "chi2_band": "filtering",
    "ParticleBelief": "filtering",
    # the localizer and its Gymnasium wrappers
    "AppearanceLocalizer": "localizer", "MEASUREMENTS": "localizer",
    "OtherCityError": "localizer", "city_info": "localizer",
    "DistrictLocalizer": "districts", "load_localizer": "loading",
    "ExperienceLocalizer": "experiences",
    "BeliefWrapper": "wrappers", "OracleWrapper": "wrappers",
    "DeadReckoningWrapper": "wrappers",
    # workflows (import the simulator)
    "fit_city_localizer": "workflows", "track_route": "workflows",
    "track_streets": "workflows", "track_metrics": "workflows",
}
__all__ = [
    "MEASUREMENTS",
    "AppearanceLocalizer",
    "BeliefFilter",
    "BeliefWrapper",
    "DeadReckoningWrapper",
    "DistrictLocalizer",
    "EfficientNetFeatures",
    "ExperienceLocalizer",
    "FeatureExtractor",
    "FunctionMeasurement",
    "GSERegressor",
    "GrassmannStiefelEigenmaps",
    "KernelRegressor",
    "OracleWrapper",
    "OtherCityError",
    "OutOfDomainError",
    "ParticleBelief",
    "PixelPCA",
    "PoseEKF",
    "PoseMeasurement",
    "RetrievalRegressor",
    "SmallCNNFeatures",
    "angular_error",
    "angular_rmse",
    "body_to_world",
    "chi2_band",
    "city_info",
    "cov_to_triu",
    "features_from_state",
    "fit_city_localizer",
    "geodesic_correlation_dimension",
    "global_dimension",
    "grid_search",
    "intrinsic_dimension_table",
    "jacobian_regression",
    "load_localizer",
    "load_recorded",
    "make_features",
    "pose_residual",
    "read_tum",
    "rmse",
    "rrmse",
    "select_n_neighbors",
    "to_body",
    "track_metrics",
    "track_route",
    "track_streets",
    "triu_to_cov",
    "wrap_angle",
    "write_tum",
]

__getattr__, __dir__ = lazy_names(__name__, _LAZY, globals())
