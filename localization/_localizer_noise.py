"""The noise model of :class:`~localization.localizer.AppearanceLocalizer` (a mixin).

Process noise and control gains from recorded motion; measurement noise R from held-out
residuals (K-fold refits on the training data, or a recorded drive with the residuals'
correlation time); the consistency calibration that runs the filter over a drive. The
maths is in :mod:`localization.filtering.measurement_noise` and :mod:`localization.filtering.process_noise`.
"""

from __future__ import annotations

from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.model_selection import KFold

from localization._validation import check_array, check_images
from localization.filtering.calibration import calibrate_consistency
from localization.filtering.measurement_noise import (
    correlation_time,
    inflate,
    robust_covariance,
)
from localization.filtering.process_noise import estimate_control_gain, estimate_process_noise
from localization.geometry import Array, to_body
from localization.gse.regressor import GSERegressor

MEASUREMENTS = ("pose", "features", "representation")


def check_data(images: ArrayLike, poses: ArrayLike, what: str = ""
               ) -> tuple[NDArray[np.uint8], Array]:
    """Validate uint8 images (n, H, W, 3) and finite poses (n, 3).

    Raises
    ------
    TypeError
        If the images or poses are not real numbers (complex, bool, strings, objects).
    ValueError
        If a shape or the images' dtype is wrong, or the poses hold NaN/inf.
    """
    images = check_images(images, f"{what}images")
    if images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"{what}images must be uint8 of shape (n, H, W, 3), got "
                         f"{images.shape} {images.dtype}")
    poses = check_array(poses, f"{what}poses", shape=(len(images), 3), what="[x, y, yaw]")
    return images, poses


class NoiseModelMixin:
    """Noise-model methods of the localizer (uses its ``regressor_``, ``transform``,
    ``_to_model``/``_from_model``, ``_new_regressor``, ``noise_folds``, ``random_state``)."""

    def fit_process_noise(self, motion_model: Any, poses: ArrayLike, controls: ArrayLike,
                          episode_starts: ArrayLike | None = None,
                          calibrate_controls: bool = True) -> Self:
        """Control gains and body-frame process noise from recorded motion (commanded
        controls against the true poses that followed them).

        Sets ``control_gain_`` (:func:`~localization.filtering.process_noise.estimate_control_gain`;
        (1, 1) with ``calibrate_controls=False``) and ``process_noise_body_``
        (:func:`~localization.filtering.process_noise.estimate_process_noise` with the calibrated
        controls). The filter predicts with ``F(x, control_gain_ * U)``.
        """
        self._check_fitted()
        gain = (estimate_control_gain(motion_model, poses, controls, episode_starts)
                if calibrate_controls else np.ones(2))
        self.process_noise_body_ = estimate_process_noise(
            motion_model, poses, np.asarray(controls, dtype=np.float64) * gain, episode_starts)
        self.control_gain_ = gain
        return self

    def fit_noise(self, motion_model: Any, images: ArrayLike, poses: ArrayLike,
                  controls: ArrayLike) -> Self:
        """Process and measurement noise from one recorded drive not used in :meth:`fit`.

        1. control gains and Q from the controls (:meth:`fit_process_noise`);
        2. R of each model from the residuals of its measurements at the true poses:
           robust covariance, inflated per component by the residuals' correlation time.

        Resets the consistency calibration (:meth:`calibrate`) and the quality report
        (``quality_``).

        Parameters
        ----------
        motion_model : object
            F (``envs.motion_model.UnicycleModel`` of the env).
        images : (n + 1, H, W, 3) uint8
            The frames of the drive, in time order (frame 0 before the first control).
        poses : (n + 1, 3)
        controls : (n, 2)
            Commanded controls; controls[t] moves the robot from frame t to t + 1.
        """
        self._check_fitted()
        images, poses, controls = self._check_drive(images, poses, controls)
        self.fit_process_noise(motion_model, poses, controls)
        self._set_noise(self._residuals(self.regressor_, self.transform(images), poses),
                        sequence=True)
        self.consistency_ = {}
        self.quality_ = {}  # it described the previous noise model
        return self

    def calibrate(self, motion_model: Any, images: ArrayLike, poses: ArrayLike,
                  controls: ArrayLike, measurements: tuple[str, ...] = MEASUREMENTS,
                  gate_probability: float | None = 0.997) -> Self:
        """Consistency calibration on a recorded drive (ideally one driven on the belief).

        The filter of each model runs over the drive from its true start pose, and Q, R and
        P0 are inflated per body component (along, cross, heading) until its covariance
        matches its errors (:func:`~localization.filtering.measurement_noise.consistency_inflation`);
        sets ``consistency_[measurement]``, starting from its current value (calibrating on a
        true-pose drive first, then on a drive on that calibrated belief, refines it). Steps
        where the filter is lost (> 1 m off) do not count; resets ``quality_``. Arguments as
        :meth:`fit_noise`.
        """
        self._check_fitted(noise=True)
        images, poses, controls = self._check_drive(images, poses, controls)
        W = self.transform(images)
        self.consistency_.update(calibrate_consistency(
            self, motion_model, W, poses, controls, measurements, gate_probability,
            self.noise_["pose"]))
        self.quality_ = {}  # it described the previous calibration
        return self

    @staticmethod
    def _check_drive(images: ArrayLike, poses: ArrayLike, controls: ArrayLike
                     ) -> tuple[NDArray[np.uint8], Array, Array]:
        images, poses = check_data(images, poses, "drive ")
        controls = np.asarray(controls, dtype=np.float64)
        if controls.shape != (len(poses) - 1, 2):
            raise ValueError(f"controls must have shape ({len(poses) - 1}, 2), got "
                             f"{controls.shape}")
        if not np.all(np.isfinite(controls)):
            raise ValueError("controls contain NaN or inf")
        return images, poses, controls

    def _set_noise(self, res: dict[str, Array], sequence: bool) -> None:
        for k, e in res.items():
            C = robust_covariance(e, self.random_state)
            tau = correlation_time(e, C) if sequence else np.ones(e.shape[1])
            self.noise_[k], self.correlation_time_[k] = inflate(C, tau), tau
            self.residual_rms_[k] = np.sqrt(np.nanmean(e ** 2, axis=0))
        e = res["pose"][np.all(np.isfinite(res["pose"]), axis=1)]
        self.initial_noise_ = e.T @ e / len(e) + 1e-9 * np.eye(3)

    def _residuals(self, reg: GSERegressor, W: Array, poses: Array) -> dict[str, Array]:
        """Residuals ``z - h(theta)`` at the true poses (NaN rows out of the domain):
        "pose" psi*(w) - theta and "representation" (dR*/dtheta)^-1 (r*(w) - R*(theta)),
        both pose errors in the body frame (along, cross, heading); "features" w - Phi*."""
        theta = self._to_model(poses)
        pose_err = self._from_model(reg.predict(W)) - poses
        J = reg.embed_pose_jacobian(theta)
        ok = np.all(np.isfinite(J), axis=(1, 2))
        rep = reg.embed(W) - reg.embed_pose(theta)
        rep_err = np.full_like(rep, np.nan)
        rep_err[ok] = np.linalg.solve(J[ok], rep[ok][..., None])[..., 0]
        return {"pose": to_body(pose_err, poses[:, 2]),
                "features": W - reg.predict_features(theta),
                "representation": to_body(rep_err, poses[:, 2])}

    def _k_fold_residuals(self, W: Array, poses: Array) -> dict[str, Array]:
        """Held-out residuals of K-fold refits (the features are fitted once on all images:
        unsupervised, they see no pose)."""
        folds = KFold(int(self.noise_folds), shuffle=True, random_state=self.random_state)
        parts: dict[str, list[Array]] = {k: [] for k in MEASUREMENTS}
        for train, test in folds.split(W):
            reg = self._new_regressor().fit(W[train], self._to_model(poses[train]))
            for k, e in self._residuals(reg, W[test], poses[test]).items():
                parts[k].append(e)
        return {k: np.concatenate(v) for k, v in parts.items()}
