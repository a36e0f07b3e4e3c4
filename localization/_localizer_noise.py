"""The noise model of :class:`~localization.localizer.AppearanceLocalizer` (a mixin).

Process noise and control gains from recorded motion; measurement noise R from held-out
residuals (K-fold refits on the training data, or a recorded drive with the residuals'
correlation time); the consistency calibration that runs the filter over a drive; the
heteroscedastic scale s(theta) of R from the K-fold residuals and the maps' local geometry
(``noise_scale_``, used by ``measurement_model(name, noise="heteroscedastic")``). The
maths is in :mod:`localization.filtering.measurement_noise`,
:mod:`localization.filtering.heteroscedastic_noise` and :mod:`localization.filtering.process_noise`.
"""

from __future__ import annotations

import warnings
from typing import Any, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import KFold

from localization._validation import check_array, check_choice, check_images
from localization.filtering.calibration import calibrate_consistency
from localization.filtering.ekf import FunctionMeasurement
from localization.filtering.heteroscedastic_noise import HeteroscedasticNoise, scaled_covariance
from localization.filtering.measurement_noise import (
    check_alpha,
    correlation_time,
    inflate,
    robust_covariance,
)
from localization.filtering.process_noise import estimate_control_gain, estimate_process_noise
from localization.geometry import Array, body_to_world, pose_residual, to_body
from localization.gse.graph import DisconnectedGraphError
from localization.gse.regressor import GSERegressor

MEASUREMENTS = ("pose", "features", "representation")
#: measurement-noise models of ``measurement_model(name, noise=...)``
NOISE_MODELS = ("global", "heteroscedastic")


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
           robust covariance, inflated per component by the residuals' correlation time;
           the heteroscedastic scales (``noise_scale_``, from :meth:`fit`'s K-fold
           residuals) are rescaled to average 1 over the drive's frames;
        3. ``novelty_ref_``: the median novelty of the drive's frames (the images R
           describes; ``BeliefFilter(novelty_noise=True)`` scales R by an image's novelty
           beyond it).

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
        W = self.transform(images)
        self._set_noise(self._residuals(self.regressor_, W, poses), sequence=True)
        u = self.regressor_.novelty(W)
        self.novelty_ref_ = float(np.nanmedian(u)) if np.isfinite(u).any() else None
        for model in getattr(self, "noise_scale_", {}).values():  # the drive's level
            model.normalize(poses, self._geometry(model, poses, W))
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

    def _fit_k_fold_noise(self, W: Array, poses: Array) -> None:
        """R of each model from K-fold held-out residuals (:meth:`_set_noise`) and its
        heteroscedastic scale ``noise_scale_[name]`` (a
        :class:`~localization.filtering.heteroscedastic_noise.HeteroscedasticNoise`)."""
        res, held, geometry = self._k_fold_residuals(W, poses)
        self._set_noise(res, sequence=False)
        self.noise_scale_ = {k: HeteroscedasticNoise().fit(e, held, self.noise_[k], geometry)
                             for k, e in res.items()}

    def _k_fold_residuals(self, W: Array, poses: Array
                          ) -> tuple[dict[str, Array], Array, Array]:
        """Held-out residuals of K-fold refits (the features are fitted once on all images:
        unsupervised, they see no pose), their poses (n, 3) and the local geometry (n, 5) of
        each fold's maps there with the images' novelty (:meth:`HeteroscedasticNoise.geometry`).

        A fold holds fewer samples than the fit; where its neighbourhood graph falls apart
        (25 samples of a corner apart from 6375 on city 12, even with 20 neighbours) the fold
        gives no residuals (a RuntimeWarning says so): the folds are random, so the others
        are an unbiased sample. ValueError if fewer than two folds are left."""
        folds = KFold(int(self.noise_folds), shuffle=True, random_state=self.random_state)
        parts: dict[str, list[Array]] = {k: [] for k in MEASUREMENTS}
        held, geometry, failed = [], [], []
        model = HeteroscedasticNoise()
        for i, (train, test) in enumerate(folds.split(W)):
            try:
                reg = self._new_regressor().fit(W[train], self._to_model(poses[train]))
            except DisconnectedGraphError as err:
                failed.append(f"fold {i}: {err}")
                continue
            for k, e in self._residuals(reg, W[test], poses[test]).items():
                parts[k].append(e)
            held.append(poses[test])
            geometry.append(model.geometry(model.density_index(poses[train]), poses[test],
                                           reg.embed_pose_jacobian(self._to_model(poses[test])),
                                           reg.novelty(W[test])))
        if failed:
            if len(held) < 2:
                raise ValueError(f"noise_folds={self.noise_folds}: fewer than two folds could "
                                 f"be fitted ({'; '.join(failed)})")
            warnings.warn(f"{len(failed)} of {self.noise_folds} noise folds left out: "
                          f"{'; '.join(failed)}", RuntimeWarning, stacklevel=3)
        return ({k: np.concatenate(v) for k, v in parts.items()}, np.concatenate(held),
                np.concatenate(geometry))

    # ------------------------------------------------- heteroscedastic noise
    def noise_scale(self, poses: ArrayLike, measurement: str, W: ArrayLike | None = None
                    ) -> Array:
        """The heteroscedastic scale ``s(theta, w)`` (n,) of the model's R at world poses
        (n, 3) for images of features W (n, m) (None: typical frames):
        ``R_body(theta) = s(theta, w) R_body``; NaN where the GSE maps have no value.

        Raises
        ------
        NotFittedError
            Without a heteroscedastic model (fit with ``noise_folds >= 2``).
        """
        model = self._noise_scale_model(measurement)
        poses = check_array(poses, "poses", shape=(None, 3), finite=False, what="[x, y, yaw]")
        return model.scale(poses, self._geometry(model, poses, W))

    def _geometry(self, model: HeteroscedasticNoise, poses: Array, W: ArrayLike | None
                  ) -> Array:
        """:meth:`HeteroscedasticNoise.geometry` (n, 5) of the fitted maps at world poses
        (n, 3) with images of features W (n, m) (None: typical frames)."""
        J = self.regressor_.embed_pose_jacobian(self._to_model(np.nan_to_num(poses)))
        J[~np.all(np.isfinite(poses), axis=1)] = np.nan
        u = None if W is None else self.regressor_.novelty(check_array(
            W, "W", shape=(len(poses), None)))
        return model.geometry(self._density_index(model), poses, J, u)

    def measurement_noise(self, poses: ArrayLike, measurement: str,
                          alpha: ArrayLike | None = None, W: ArrayLike | None = None) -> Array:
        """Heteroscedastic R(theta) at world poses (n, 3): (n, 3, 3) world-frame pose-error
        covariances ``T(yaw) s(theta) R_body T(yaw)^T`` for "pose" and "representation"
        (the representation model's R is ``H R(theta) H^T``), (n, m, m) ``s(theta) R`` for
        "features"; R_body inflated by ``alpha`` (default the calibrated consistency); W as
        :meth:`noise_scale`. NaN matrices where the maps have no value; symmetric positive
        definite elsewhere."""
        alpha = self.consistency(measurement) if alpha is None else check_alpha(alpha)
        s = self.noise_scale(poses, measurement, W)
        if measurement == "features":
            return scaled_covariance(self.noise_["features"] * float(np.mean(alpha)), s)
        R = scaled_covariance(inflate(self.noise_[measurement], alpha), s)
        poses = np.asarray(poses, dtype=np.float64)
        return np.array([body_to_world(Rb, float(p[2])) if np.isfinite(p[2]) else Rb
                         for Rb, p in zip(R, poses)]).reshape(R.shape)

    def _noise_scale_model(self, measurement: str) -> HeteroscedasticNoise:
        check_choice(measurement, "measurement", MEASUREMENTS)
        self._check_fitted(noise=True)
        model = getattr(self, "noise_scale_", {}).get(measurement)
        if model is None:
            raise NotFittedError("no heteroscedastic noise model: fit with noise_folds >= 2 "
                                 "(it is learned from the K-fold held-out residuals)")
        return model

    def _density_index(self, model: HeteroscedasticNoise) -> Any:
        """Neighbour index of the training poses (cached; rebuilt after partial_fit)."""
        theta = self.regressor_.theta_
        key = (id(theta), len(theta), model.heading_scale, model.density_neighbors)
        cache = getattr(self, "_density_cache", None)
        if cache is None or cache[0] != key:
            cache = (key, model.density_index(self._from_model(theta)))
            self._density_cache = cache
        return cache[1]

    def _heteroscedastic_model(self, measurement: str, alpha: Array) -> HeteroscedasticMeasurement:
        """``measurement_model(measurement, alpha, noise="heteroscedastic")``: the global
        model's h, H and residual with ``R(x) = s(x, w) R`` for the image last passed to
        ``observe(w)`` (a typical frame before) and ``gate_R(x) = s(x) R`` (a typical frame:
        the NIS gate does not widen for an unfamiliar image). Where the maps have no value
        the pose model takes s = ``max_scale``; the other two models have no H there."""
        model = self._noise_scale_model(measurement)
        reg, to_model = self.regressor_, self._to_model
        index = self._density_index(model)
        cache: dict[str, Array] = {}

        def J(x: Array) -> Array:  # the filter asks for H and R at the same x
            if "x" not in cache or not np.array_equal(cache["x"], x):
                cache["x"], cache["J"] = np.array(x), reg.embed_pose_jacobian(to_model(x))[0]
            return cache["J"]

        def s(x: Array, image: bool = True) -> float:
            x = np.asarray(x, dtype=np.float64).reshape(1, 3)
            u = None if out.novelty is None or not image else np.array([out.novelty])
            v = float(model.scale(x, model.geometry(index, x, J(x[0])[None], u))[0])
            return v if np.isfinite(v) else float(model.max_scale)

        if measurement == "features":
            Rf = self.noise_["features"] * float(np.mean(alpha))
            out = HeteroscedasticMeasurement(
                reg, h=lambda x: reg.predict_features(to_model(x))[0],
                H=lambda x: reg.features_jacobian(to_model(x))[0], R=lambda x: s(x) * Rf,
                gate_R=lambda x: s(x, False) * Rf)
            return out
        Rb = inflate(self.noise_[measurement], alpha)
        if measurement == "pose":
            out = HeteroscedasticMeasurement(
                reg, h=lambda x: np.array(x, dtype=np.float64), H=lambda x: np.eye(3),
                R=lambda x: body_to_world(s(x) * Rb, float(x[2])), residual=pose_residual,
                gate_R=lambda x: body_to_world(s(x, False) * Rb, float(x[2])))
            return out

        def R_rep(x: Array, image: bool = True) -> Array:
            Hx = J(x)
            return Hx @ body_to_world(s(x, image) * Rb, float(x[2])) @ Hx.T

        out = HeteroscedasticMeasurement(reg, h=lambda x: reg.embed_pose(to_model(x))[0], H=J,
                                         R=R_rep, gate_R=lambda x: R_rep(x, False))
        return out


class HeteroscedasticMeasurement(FunctionMeasurement):
    """A :class:`FunctionMeasurement` whose R(x) also depends on the current image:
    :meth:`observe` sets its novelty (the belief filter calls it before each update);
    ``gate_R(x)``, the R of a typical image, is what the EKF's NIS gate uses."""

    def __init__(self, regressor: GSERegressor, gate_R: Any, **model: Any) -> None:
        super().__init__(**model)
        self._regressor = regressor
        self.gate_R = gate_R
        self.novelty: float | None = None

    def observe(self, w: ArrayLike) -> None:
        """The features w (m,) of the image of the next update."""
        u = float(self._regressor.novelty(np.asarray(w, dtype=np.float64).reshape(1, -1))[0])
        self.novelty = u if np.isfinite(u) else None
