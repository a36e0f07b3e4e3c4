"""AppearanceLocalizer: images -> features -> GSE regression -> pose, with noise models.

It bundles what a filter needs to localize from images (seed paper section III.D):

- an image region (rows of the image) and a feature extractor ``omega``
  (:mod:`localization.features.base`);
- a :class:`~localization.gse.regressor.GSERegressor` giving psi* (features -> pose),
  Phi* (pose -> features) and the representation maps r*, R*;
- measurement noise covariances R of the three measurement models, estimated from
  held-out residuals (:mod:`localization.filtering.measurement_noise`): robustly
  (:class:`sklearn.covariance.MinCovDet`, so the rare aliasing errors do not inflate R; the
  filter's NIS gate rejects those at run time), in the body frame (along track, cross
  track, heading) for the pose-like models. :meth:`AppearanceLocalizer.fit` takes them from
  K-fold refits on the training data; :meth:`AppearanceLocalizer.fit_noise` from a recorded
  drive (held out from the fit), inflated by the residuals' correlation time, and then
  calibrates the filter's consistency on that drive;
- the control gains and body-frame process noise ``Q_body`` of the motion model F,
  estimated from recorded motion (:mod:`localization.filtering.process_noise`).

The three measurement models (chosen by name in :meth:`AppearanceLocalizer.measurement_model`):

====================  ==================  ===================  ========================
name                  z                   h(theta)             H
====================  ==================  ===================  ========================
``"pose"``            psi*(w)             theta                I (3 x 3)
``"features"``        w                   Phi*(theta)          dPhi*/dtheta (m x 3)
``"representation"``  r*(w)               R*(theta)            dR*/dtheta (q x 3)
====================  ==================  ===================  ========================

The heading is periodic and GSE cuts its circle open at +-pi (docs/method.md §10):
a neighbourhood graph must not link samples across the cut, so every street driven
along heading ~pi would be split lengthwise into two halves. The localizer therefore
fits GSE on a rotated heading ``yaw - yaw_cut_ + pi`` whose cut lies at the heading
where the training poses are sparsest (``yaw_cut="auto"``; on a street grid: a diagonal,
crossed only in the middle of turns).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sklearn.exceptions import NotFittedError

from localization._localizer_belief import BeliefInterfaceMixin
from localization._localizer_features import ImageFeaturesMixin
from localization._localizer_io import load_localizer, save_localizer
from localization._localizer_map import (  # noqa: F401  (city_info, OtherCityError: public here)
    MapMixin,
    OtherCityError,
    check_city_info,
    city_info,
    images_fingerprint,
)
from localization._localizer_noise import MEASUREMENTS, NoiseModelMixin, check_data
from localization._validation import (
    check_array,
    check_choice,
    check_int,
    check_real,
    check_seed,
)
from localization.features import make_features
from localization.geometry import Array, wrap_angle
from localization.gse.graph import fit_main_component
from localization.gse.inverse import feature_whitener, refine_poses, verify_poses
from localization.gse.regressor import GSERegressor
from localization.turned_views import check_turn_camera, turned_prediction

_YAW_BINS = 72

#: :class:`GSERegressor` settings of the localizer (``regressor_params`` overrides them).
#: On lane images GSERegressor's generic defaults (20 neighbours, pose block scaled 2x the
#: features' sensitivity) let images that look alike at different places become neighbours
#: of the joint (w, theta) graph: the embedding folds, psi* and r* alias. City 0, 10000
#: "streets" lane images, 2000 held out: psi* off by > 1 m for 39 % of them (20 / 2.0);
#: 18 % with 10 neighbours; 2.8 % with 10 neighbours and the pose block 5x (a nearest
#: neighbour lookup: 2.6 %), median error 0.09 m along / 0.08 m across. A pose scale of 10
#: or 20 changes nothing more; 15 or 20 neighbours are worse again. No loop cut: a 3-D
#: embedding of (x, y, yaw) needs none, and on the street grid GSERegressor's loop test fired
#: on the outer ring of streets (city 0, 10000 images: same 29/30 goals, fit 16 s vs 19 s).
REGRESSOR_DEFAULTS: dict[str, Any] = {"n_neighbors": 10, "theta_scale_factor": 5.0,
                                      "loop_cut": "none"}


def sparsest_heading(yaw: ArrayLike, bins: int = _YAW_BINS) -> float:
    """Centre of the least populated of ``bins`` equal heading bins (ties: the first)."""
    counts, edges = np.histogram(wrap_angle(np.asarray(yaw)), bins=bins, range=(-np.pi, np.pi))
    i = int(np.argmin(counts))
    return float(0.5 * (edges[i] + edges[i + 1]))


class AppearanceLocalizer(ImageFeaturesMixin, NoiseModelMixin, BeliefInterfaceMixin, MapMixin):
    """Localize a camera from its images: image rows + features + GSE regression + noise.

    Parameters
    ----------
    features : str
        Feature extractor name for :func:`localization.features.base.make_features`
        ("pixel_pca", "efficientnet", "small_cnn").
    features_params : dict, optional
        Keyword arguments of the extractor.
    rows : (float, float)
        Fractions ``[start, stop)`` of the image height fed to the features. The default
        ``(0.0, 0.55)`` keeps the horizon and what is above it: the road just in front of
        a low camera (lane stripes, crosswalks) makes features change fast with small
        translations, which local regression cannot follow.
    regressor_params : dict, optional
        Keyword arguments of :class:`GSERegressor` on top of ``REGRESSOR_DEFAULTS``
        (``periodic=(2,)`` and ``out_of_domain="nan"`` are always set).
    noise_folds : int
        Folds of the held-out residuals that estimate R in :meth:`fit` (>= 2), or 0 to
        skip them (R then comes from :meth:`fit_noise`).
    yaw_cut : "auto" or float
        Heading (rad) where GSE cuts the heading circle; "auto" = the sparsest heading
        of the training poses.
    random_state : int
        Seed of the fold split and the robust covariance.
    max_dropped : float in [0, 1)
        Largest share of the training images that may be dropped because GSE's
        neighbourhood graph cuts them off from the rest (a few views of a dead end or a
        corner; a RuntimeWarning says how many); a larger split raises
        :class:`~localization.gse.graph.DisconnectedGraphError`. 0: any split raises.

    Attributes
    ----------
    features_, regressor_ :
        The fitted extractor and :class:`GSERegressor` (on poses with the rotated heading).
    yaw_cut_ : float
    noise_ : dict of str -> ndarray
        R per measurement model: "pose" and "representation" (3, 3) pose-error covariances
        in the body frame, "features" (m, m); inflated by ``correlation_time_``.
    noise_scale_ : dict of str -> HeteroscedasticNoise
        Per measurement model, the heteroscedastic scale s(theta) of R learned from the
        K-fold residuals (``noise_folds >= 2``; empty otherwise; kept by :meth:`fit_noise`,
        which re-estimates the level R): used by ``measurement_model(name,
        noise="heteroscedastic")`` (:mod:`localization.filtering.heteroscedastic_noise`).
    initial_noise_ : ndarray (3, 3)
        Plain (not robust) second moment of the pose residuals in the body frame: the
        covariance of the initial belief, which must cover psi*'s rare metre-scale errors.
    correlation_time_, residual_rms_ : dict of str -> ndarray
        Per-component correlation time (1 for K-fold residuals) and plain residual RMS.
    consistency_ : dict of str -> ndarray (3,)
        Body-frame inflation of Q, R and P0 per measurement model (:meth:`fit_noise`).
    control_gain_ : ndarray (2,)
    process_noise_body_ : ndarray (3, 3) or None
    camera_ : str or None
    image_size_ : (int, int)
    city_ : dict or None
        The city of the training images (``city_info(env)``; None: unknown, e.g. recorded
        data); :meth:`check_city` refuses another one.
    dropped_ : ndarray of shape (n_dropped,)
        Indices of the training images left out of the GSE maps (``max_dropped``).
    fingerprint_ : str
        SHA-256 of a fixed subsample of the training images (:func:`images_fingerprint`).
    quality_ : dict of str -> float
        The quality report of :func:`~localization.workflows.tracking.fit_city_localizer`
        (empty until then; reset by a refit, :meth:`fit_noise` and :meth:`calibrate`).
    """

    def __init__(self, features: str = "pixel_pca", features_params: dict | None = None,
                 rows: tuple[float, float] = (0.0, 0.55), regressor_params: dict | None = None,
                 noise_folds: int = 3, yaw_cut: str | float = "auto",
                 random_state: int = 0, max_dropped: float = 0.02) -> None:
        self.features = features
        self.features_params = features_params
        self.rows = rows
        self.regressor_params = regressor_params
        self.noise_folds = noise_folds
        self.yaw_cut = yaw_cut
        self.random_state = random_state
        self.max_dropped = max_dropped

    # ------------------------------------------------------------------ fit
    def fit(self, images: ArrayLike, poses: ArrayLike, *, camera: str | None = None,
            city: dict[str, Any] | None = None) -> AppearanceLocalizer:
        """Fit features, the GSE regression and (``noise_folds >= 2``) the measurement noise.

        Parameters
        ----------
        images : ndarray of shape (n, H, W, 3), uint8
        poses : ndarray of shape (n, 3)
            True poses [x, y, yaw] where the images were taken.
        camera : str, optional
            Camera name of the env that made the images (the wrapper checks it).
        city : dict, optional
            The env's city, ``city_info(env)``: stored as ``city_`` so :meth:`check_city`
            can refuse another city. With the camera these describe the data, so they are
            arguments of ``fit`` (like scikit-learn's ``feature_names_in_``, taken from X):
            a separate setter could pair a city with images of another.

        Returns
        -------
        self
        """
        self._check_params()
        images, poses = check_data(images, poses)
        if camera is not None and not isinstance(camera, str):
            raise TypeError(f"camera must be a camera name (str) or None, got {type(camera).__name__}")
        city = check_city_info(city)
        self._row_slice(images.shape[1])  # validates rows
        if isinstance(self.yaw_cut, str):
            self.yaw_cut_ = sparsest_heading(poses[:, 2])
        else:
            self.yaw_cut_ = float(wrap_angle(float(self.yaw_cut)))
        self.camera_, self.city_ = camera, city
        self.fingerprint_ = images_fingerprint(images)
        self.quality_: dict[str, float] = {}
        self.image_size_ = (int(images.shape[1]), int(images.shape[2]))
        self.features_ = make_features(self.features, **(self.features_params or {}))
        W = self.features_.fit_transform(self._crop(images), poses)  # only small_cnn uses poses
        Y = self._to_model(poses)
        self.regressor_, kept = fit_main_component(
            lambda i: self._new_regressor().fit(W[i], Y[i]), len(W), self.max_dropped,
            "the training images")
        self.dropped_ = np.setdiff1d(np.arange(len(W)), kept)
        W, poses = W[kept], poses[kept]
        self.noise_: dict[str, Array] = {}
        self.correlation_time_: dict[str, Array] = {}
        self.residual_rms_: dict[str, Array] = {}
        self.consistency_: dict[str, Array] = {}
        self.initial_noise_: Array | None = None
        self.noise_scale_: dict[str, Any] = {}
        if int(self.noise_folds) >= 2:
            self._fit_k_fold_noise(W, poses)
        self.process_noise_body_: Array | None = None
        self.control_gain_ = np.ones(2)
        return self

    def partial_fit(self, images: ArrayLike, poses: ArrayLike) -> AppearanceLocalizer:
        """Add images of new places to the fitted localizer without a refit.

        The images go through the fitted feature extractor and
        :meth:`GSERegressor.partial_fit <localization.gse.regressor.GSERegressor.partial_fit>`
        adds them to the GSE regression by a local update (docs/method.md §18): a robot
        maps a new street, and ``predict`` covers it at once. Kept as fitted: the
        features, the heading cut ``yaw_cut_``, the measurement noise and its calibration
        (call :meth:`fit_noise` to re-estimate them on data of the new places),
        ``fingerprint_``, ``city_`` and ``camera_``.

        Parameters
        ----------
        images : ndarray of shape (n, H, W, 3), uint8
            The fitted image size.
        poses : ndarray of shape (n, 3)
            True poses [x, y, yaw] where the images were taken.

        Returns
        -------
        self
        """
        self._check_fitted()
        images, poses = check_data(images, poses)
        W = self.transform(images)
        self.regressor_.partial_fit(W, self._to_model(poses))
        return self

    def _check_params(self) -> None:
        """Validate the constructor's hyperparameters (scikit-learn style: at fit time)."""
        if not isinstance(self.features, str):
            raise TypeError(f"features must be an extractor name (str), got "
                            f"{type(self.features).__name__}")
        for name in ("features_params", "regressor_params"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, dict):
                raise TypeError(f"{name} must be a dict or None, got {type(value).__name__}")
        rows = check_array(self.rows, "rows", shape=(2,), what="(start, stop) fractions")
        if not 0.0 <= rows[0] < rows[1] <= 1.0:
            raise ValueError(f"rows must be fractions 0 <= start < stop <= 1, got {self.rows}")
        folds = check_int(self.noise_folds, "noise_folds", low=0)
        if folds == 1:
            raise ValueError(f"noise_folds must be 0 or >= 2, got {self.noise_folds}")
        if isinstance(self.yaw_cut, str):
            if self.yaw_cut != "auto":
                raise ValueError(f"yaw_cut must be 'auto' or a number, got {self.yaw_cut!r}")
        else:
            check_real(self.yaw_cut, "yaw_cut")
        check_seed(self.random_state, "random_state")
        check_real(self.max_dropped, "max_dropped", low=0.0, high=1.0, high_open=True)

    def to_model(self, poses: ArrayLike) -> Array:
        """World poses (n, 3) -> the regressor's poses (n, 3): the heading rotated so that
        GSE's cut of the circle (``yaw_cut_``) lies at +-pi (docs/method.md §10)."""
        out = np.array(poses, dtype=np.float64, copy=True).reshape(-1, 3)
        out[:, 2] = wrap_angle(out[:, 2] - self.yaw_cut_ + np.pi)
        return out

    def from_model(self, theta: ArrayLike) -> Array:
        """Inverse of :meth:`to_model`: the regressor's poses (n, 3) -> world poses (n, 3)."""
        out = np.array(theta, dtype=np.float64, copy=True).reshape(-1, 3)
        out[:, 2] = wrap_angle(out[:, 2] + self.yaw_cut_ - np.pi)
        return out

    _to_model = to_model
    _from_model = from_model

    def _new_regressor(self) -> GSERegressor:
        params = {**REGRESSOR_DEFAULTS, **(self.regressor_params or {}), "periodic": (2,),
                  "out_of_domain": "nan"}
        return GSERegressor(**params)

    # -------------------------------------------------------------- predict
    def _check_fitted(self, noise: bool = False) -> None:
        if not hasattr(self, "regressor_"):
            raise NotFittedError("this AppearanceLocalizer is not fitted yet: call fit() first")
        if noise and set(self.noise_) != set(MEASUREMENTS):
            raise NotFittedError("no measurement noise: fit with noise_folds >= 2 or call "
                                 "fit_noise()")

    def predict(self, images: ArrayLike, refine: int = 0, verify: int = 0,
                verify_margin: float = 3.0, turns: int = 0) -> Array:
        """psi*(X): poses (n, 3) of images (n, H, W, 3); NaN rows for images whose
        features lie outside the training domain.

        ``verify`` > 0: psi*(w) is checked against the poses of that many training images
        nearest to w in feature space, and replaced by the one whose Phi* explains w
        ``verify_margin`` times better under the features' noise R, if any
        (:func:`~localization.gse.inverse.verify_poses`, docs/method.md §8.4; 10 and 3 on
        tuning cities 11-12, nine appearance presets each: within (0.25 m, 2 deg) / (5 m,
        10 deg) 74.8 / 98.6 -> 75.8 / 99.2 % on average, neutral on city 11, +2 / +1.4 on
        city 12). Rows out of the domain stay NaN. ``refine`` > 0: then that many Gauss-Newton
        steps towards the pose whose Phi* best explains w under R
        (:func:`~localization.gse.inverse.refine_poses`; 3 steps: on tuning cities 12-13
        the median error of street-wide single images fell by 20-29 %). Both need
        ``noise_["features"]`` (NotFittedError without: fit with ``noise_folds >= 2`` or
        call :meth:`fit_noise`). ``turns`` > 0 (perspective camera only): the position is the
        median over the image and its views shifted by 1..``turns`` pixels either way, each
        estimated as above (:mod:`localization.turned_views`; the heading stays the image's
        own, and rows out of the domain stay NaN; 2 on tuning cities 11-12: within (0.25 m,
        2 deg) 74.9 -> 80.7 % on average over four appearance presets)."""
        refine = check_int(refine, "refine", low=0)
        verify = check_int(verify, "verify", low=0)
        verify_margin = check_real(verify_margin, "verify_margin", low=1.0)
        turns = check_int(turns, "turns", low=0)
        self._check_fitted(noise=refine > 0 or verify > 0)
        if turns:
            check_turn_camera(self.camera_)
        return turned_prediction(
            lambda views: self._from_model(self._predict_view(views, refine, verify,
                                                              verify_margin)),
            self.check_images(images), turns)

    def _predict_view(self, images: ArrayLike, refine: int, verify: int, verify_margin: float
                      ) -> Array:
        """psi* of each image in the regressor's poses (n, 3), verified and refined as
        :meth:`predict` says."""
        W = self.transform(images)
        theta = self.regressor_.predict(W)
        L = self.feature_whitener() if verify or refine else None
        if verify:
            theta, _ = verify_poses(self.regressor_, W, theta, L, verify, verify_margin)
        if refine:
            theta = refine_poses(self.regressor_, W, theta, L, refine)
        return theta

    def feature_whitener(self) -> Array:
        """L (m, m) with ``L R L^T = I`` for the features' noise R (``noise_["features"]``)."""
        self._check_fitted(noise=True)
        return feature_whitener(self.noise_["features"])

    def measure(self, w: ArrayLike, measurement: str) -> Array:
        """The measurement z of the named model from one feature vector w (m,).

        NaN entries mean that w lies outside the training domain (no measurement).
        """
        self._check_fitted()
        check_choice(measurement, "measurement", MEASUREMENTS)
        w = check_array(w, "w")
        if w.ndim != 1 and w.shape[:-1] != (1,) * (w.ndim - 1):
            raise ValueError(f"w must be one feature vector of shape (m,), got shape {w.shape}")
        w = w.reshape(1, -1)
        if measurement == "pose":
            return self._from_model(self.regressor_.predict(w))[0]
        if measurement == "features":
            return w[0].copy()
        if measurement == "representation":
            return self.regressor_.embed(w)[0]
        raise ValueError(f"unknown measurement {measurement!r}; choose one of {MEASUREMENTS}")

    # ---------------------------------------------------------------- save
    def get_params(self) -> dict[str, Any]:
        """Constructor arguments (JSON-friendly)."""
        return {"features": self.features, "features_params": self.features_params,
                "rows": list(self.rows), "regressor_params": self.regressor_params,
                "noise_folds": self.noise_folds, "yaw_cut": self.yaw_cut,
                "random_state": self.random_state}

    def save(self, path: str | Path) -> None:
        """Save to one ``.npz`` (no pickle): settings as JSON, arrays by name. The parent
        folder is created if missing."""
        self._check_fitted()
        save_localizer(self, path)

    @classmethod
    def load(cls, path: str | Path) -> AppearanceLocalizer:
        """Load a localizer written by :meth:`save` (``allow_pickle=False``).

        Raises
        ------
        FileNotFoundError
            If there is no such file.
        ValueError
            If the file is not a saved localizer, is corrupted or incomplete.
        """
        return load_localizer(cls, path)

