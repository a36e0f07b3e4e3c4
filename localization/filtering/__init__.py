"""Filtering: the pose EKF, its noise models and the image-fed pose belief (no Gym, no
simulator: runs on recorded data).

- :class:`PoseEKF` (filterpy's ``ExtendedKalmanFilter``) with a known motion model F, the
  measurement models :class:`FunctionMeasurement` / :class:`PoseMeasurement`, the NIS gate;
- process noise Q from recorded motion (:func:`estimate_process_noise`,
  :func:`estimate_control_gain`, :func:`world_process_noise`);
- measurement noise R from residuals (:func:`robust_covariance`, :func:`correlation_time`,
  :func:`inflate`) and the consistency calibration (:func:`calibrate_consistency`); R
  scaled by the filter's own innovations (:class:`InnovationScale`); a persistent
  measurement bias carried beside the pose (:class:`BiasedPoseEKF`, :class:`MeasurementBias`);
- :class:`BeliefFilter`: the EKF fed with image features by a fitted localizer, with its
  divergence detection (:class:`DivergenceMonitor`);
- :class:`ParticleBelief`: the multi-hypothesis (particle-filter) belief.
"""

from localization.filtering.adaptive_noise import InnovationScale, ScaledMeasurement
from localization.filtering.belief import STATUSES, BeliefFilter
from localization.filtering.calibration import calibrate_consistency
from localization.filtering.divergence import BELIEF_STATUSES, DivergenceMonitor
from localization.filtering.ekf import (
    FunctionMeasurement,
    MeasurementModel,
    OutOfDomainError,
    PoseEKF,
    PoseMeasurement,
    UpdateResult,
    chi2_band,
    control_noise_Q,
    numerical_jacobian,
)
from localization.filtering.localizer_protocol import Localizer
from localization.filtering.measurement_bias import BiasedPoseEKF, MeasurementBias
from localization.filtering.measurement_noise import (
    consistency_inflation,
    correlation_time,
    inflate,
    robust_covariance,
)
from localization.filtering.particles import PARTICLE_STATUSES, ParticleBelief
from localization.filtering.process_noise import (
    estimate_control_gain,
    estimate_process_noise,
    prediction_errors,
    world_process_noise,
)

__all__ = [
    "BELIEF_STATUSES",
    "PARTICLE_STATUSES",
    "STATUSES",
    "BeliefFilter",
    "BiasedPoseEKF",
    "DivergenceMonitor",
    "FunctionMeasurement",
    "InnovationScale",
    "Localizer",
    "MeasurementBias",
    "MeasurementModel",
    "OutOfDomainError",
    "ParticleBelief",
    "PoseEKF",
    "PoseMeasurement",
    "ScaledMeasurement",
    "UpdateResult",
    "calibrate_consistency",
    "chi2_band",
    "consistency_inflation",
    "control_noise_Q",
    "correlation_time",
    "estimate_control_gain",
    "estimate_process_noise",
    "inflate",
    "numerical_jacobian",
    "prediction_errors",
    "robust_covariance",
    "world_process_noise",
]
