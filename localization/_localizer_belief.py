"""The pose-belief interface of :class:`~localization.localizer.AppearanceLocalizer` (a
mixin): what a filter asks the localizer for, the measurement models (h, H, R), the
initial and know-nothing beliefs and the process noise Q(x).

The host class provides ``regressor_``, ``noise_``, ``initial_noise_``,
``process_noise_body_``, ``consistency_``, ``measure``, ``_check_fitted``, ``_to_model``
and ``_from_model``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sklearn.exceptions import NotFittedError

from localization._localizer_noise import MEASUREMENTS, NOISE_MODELS
from localization._validation import check_array, check_choice
from localization.filtering.ekf import FunctionMeasurement
from localization.filtering.measurement_noise import check_alpha as _check_alpha
from localization.filtering.measurement_noise import inflate
from localization.filtering.process_noise import world_process_noise
from localization.geometry import Array, body_to_world, pose_residual

__all__ = ["BeliefInterfaceMixin"]


class BeliefInterfaceMixin:
    """Measurement models, beliefs and process noise of a fitted localizer."""

    regressor_: Any
    noise_: dict[str, Any]

    def consistency(self, measurement: str) -> Array:
        """Calibrated body-frame inflation (3,) of the model (ones when not calibrated)."""
        return np.asarray(getattr(self, "consistency_", {}).get(measurement, np.ones(3)))

    def measurement_model(self, measurement: str, alpha: ArrayLike | None = None,
                          noise: str = "global") -> FunctionMeasurement:
        """The filter's measurement model (h, H, R, residual) of the named kind.

        "pose": ``h(x) = x``, ``H = I``, ``R(x) = T(yaw) R_body T(yaw)^T``;
        "representation": ``h = R*``, ``H = dR*/dtheta``, ``R(x) = H T R_body T^T H^T``
        (R_body: the pose-equivalent noise in the body frame); "features": ``h = Phi*``,
        ``H = dPhi*/dtheta``, a constant R. R_body is inflated by ``alpha`` (default the
        calibrated ``consistency(measurement)``), the features' R by its mean. ``h`` and
        ``H`` are NaN outside the training domain. ``noise="heteroscedastic"``: R scaled by
        ``s(x)`` (``noise_scale_``, docs/method.md §15.4).
        """
        check_choice(measurement, "measurement", MEASUREMENTS)
        check_choice(noise, "noise", NOISE_MODELS)
        self._check_fitted(noise=True)
        alpha = self.consistency(measurement) if alpha is None else _check_alpha(alpha)
        if noise == "heteroscedastic":
            return self._heteroscedastic_model(measurement, alpha)
        reg, to_model = self.regressor_, self._to_model
        if measurement == "features":
            return FunctionMeasurement(
                h=lambda x: reg.predict_features(to_model(x))[0],
                H=lambda x: reg.features_jacobian(to_model(x))[0],
                R=self.noise_["features"] * float(np.mean(alpha)))
        R = inflate(self.noise_[measurement], alpha)
        if measurement == "pose":
            return FunctionMeasurement(h=lambda x: np.array(x, dtype=np.float64),
                                       H=lambda x: np.eye(3),
                                       R=lambda x: body_to_world(R, float(x[2])),
                                       residual=pose_residual)
        cache: dict[str, Array] = {}

        def H(x: Array) -> Array:  # the filter asks for H and R at the same x
            if "x" not in cache or not np.array_equal(cache["x"], x):
                cache["x"], cache["H"] = np.array(x), reg.embed_pose_jacobian(to_model(x))[0]
            return cache["H"]

        def R_rep(x: Array) -> Array:
            Hx = H(x)
            return Hx @ body_to_world(R, float(x[2])) @ Hx.T

        return FunctionMeasurement(h=lambda x: reg.embed_pose(to_model(x))[0], H=H, R=R_rep)

    def initial_belief(self, w: ArrayLike) -> tuple[Array, Array]:
        """Belief (mean (3,), covariance (3, 3)) from one image's features: psi*(w) with the
        plain second moment of psi*'s residuals at that heading (``initial_noise_``: unlike
        R it counts the rare aliasing errors, which a single image cannot be gated
        against). The mean is NaN when w is out of the training domain."""
        self._check_fitted(noise=True)
        x0 = self.measure(w, "pose")
        yaw = float(x0[2]) if np.isfinite(x0[2]) else 0.0
        return x0, body_to_world(self.initial_noise_, yaw)

    def prior(self) -> tuple[Array, Array]:
        """Mean (3,) and covariance (3, 3) of the training poses: a know-nothing belief."""
        self._check_fitted()
        poses = self._from_model(self.regressor_.theta_)
        return (np.array([*poses[:, :2].mean(axis=0), 0.0]),
                np.diag([*poses[:, :2].var(axis=0), np.pi ** 2 / 3.0]))

    def check_ready(self) -> None:
        """Raise NotFittedError unless the localizer can drive a pose belief: fitted, with its
        measurement noise and its process noise (:meth:`fit_noise`)."""
        self._check_fitted(noise=True)
        if getattr(self, "process_noise_body_", None) is None:
            raise NotFittedError("the localizer has no process noise: call fit_noise() or "
                                 "fit_process_noise() first")

    def process_noise(self, pose: ArrayLike, alpha: ArrayLike | None = None) -> Array:
        """Q(x) (3, 3) in the world frame at ``pose``: ``T(yaw) Q_body T(yaw)^T`` with
        Q_body inflated by ``alpha`` (default none)."""
        if getattr(self, "process_noise_body_", None) is None:
            raise NotFittedError("process noise not estimated: call fit_noise() or "
                                 "fit_process_noise() first")
        pose = check_array(pose, "pose", shape=(3,), what="[x, y, yaw]")
        alpha = None if alpha is None else _check_alpha(alpha)
        Q = self.process_noise_body_ if alpha is None else inflate(self.process_noise_body_, alpha)
        return world_process_noise(Q, pose)
