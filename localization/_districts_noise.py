"""Noise model of :class:`~localization.districts.DistrictLocalizer` (a mixin): Q and the
control gains from a recorded drive, R pooled over the districts for the pose-like models
and per district for the features, and the consistency of the hand-over filter.

The host class provides ``districts_``, ``_views``, ``cells_``, ``overlap``,
``n_features_``, ``district_of``, ``owners``, ``transform``, ``check_ready`` and
``_check_fitted``; an :class:`~localization.experiences.ExperienceLocalizer` (one map per
look) overrides ``_region``: a look's features' R comes from the frames it measured.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._localizer_noise import MEASUREMENTS
from localization.filtering.calibration import calibrate_consistency
from localization.geometry import Array
from localization.localizer import AppearanceLocalizer

__all__ = ["DistrictNoiseMixin", "inside", "provisional_noise"]

_MIN_FRAMES = 200  # the correlation time's blocks (measurement_noise.correlation_time)
_RESIDUAL_SAMPLE = 3000  # training images per map for its provisional noise


def inside(xy: Array, box: Array, margin: float = 0.0) -> Array:
    """Mask (n,) of the points (n, 2) within ``margin`` of the box [x0, y0, x1, y1]."""
    return ((xy[:, 0] >= box[0] - margin) & (xy[:, 0] <= box[2] + margin)
            & (xy[:, 1] >= box[1] - margin) & (xy[:, 1] <= box[3] + margin))


def provisional_noise(loc: AppearanceLocalizer, images: Any, poses: Array, seed: int) -> None:
    """Without a K-fold noise model, give ``loc`` one from its training residuals (a sample
    of at most 3000 of its training images, drawn with ``seed``)."""
    if set(loc.noise_) != set(MEASUREMENTS):
        sub = np.random.default_rng(seed).permutation(len(poses))[:_RESIDUAL_SAMPLE]
        W = loc.transform(images[sub])
        loc._set_noise(loc._residuals(loc.regressor_, W, poses[sub]), sequence=False)


class DistrictNoiseMixin:
    """Noise-model methods of the district localizer."""

    districts_: list[AppearanceLocalizer]
    _views: list[Any]
    cells_: Array
    overlap: float
    n_features_: int
    consistency_: dict[str, Array]
    quality_: dict[str, float]

    def fit_noise(self, motion_model: Any, images: ArrayLike, poses: ArrayLike,
                  controls: ArrayLike) -> Any:
        """Q, the control gains and R from one recorded drive (see the module docstring);
        arguments as :meth:`AppearanceLocalizer.fit_noise`. Resets the consistency."""
        self._check_fitted()
        images, poses, controls = AppearanceLocalizer._check_drive(images, poses, controls)
        first = self.districts_[0].fit_process_noise(motion_model, poses, controls)
        self.control_gain_ = np.array(first.control_gain_)
        self.process_noise_body_ = np.array(first.process_noise_body_)
        for d in self.districts_:
            d.control_gain_, d.process_noise_body_ = self.control_gain_, self.process_noise_body_
        W = self.transform(images)
        owner = self.owners(poses, W)
        pooled = self._pooled_residuals(W, poses, owner)
        thin = []
        for k, view in enumerate(self._views):
            res = dict(pooled)
            region = self._region(k, poses, owner)
            features = self._region_features(view, W[region], poses[region])
            if features is None:
                thin.append(f"{k} ({int(region.sum())} frames)")
            else:
                res["features"] = features
            view.localizer._set_noise(res, sequence=True)
            view.localizer.consistency_, view.localizer.quality_ = {}, {}
        if thin:
            warnings.warn(f"the drive passes too few frames through districts {', '.join(thin)} "
                          f"(< {self._min_frames()}) for their features' R: their training "
                          "residuals' stays (a longer drive estimates it)", RuntimeWarning,
                          stacklevel=2)
        self.consistency_, self.quality_ = {}, {}
        return self

    def _region(self, k: int, poses: Array, owner: Array) -> Array:
        """Mask (n,) of the drive's frames whose features' R district k learns: those within
        ``overlap`` of its cell (``owner``: the map that measures each frame, unused)."""
        return inside(poses[:, :2], self.cells_[k], float(self.overlap))

    def _min_frames(self) -> int:
        """Finite drive residuals a district needs for its own features' R (a robust
        covariance of m components needs 5 m, and its correlation time 200)."""
        return max(5 * self.n_features_, _MIN_FRAMES)

    def _region_features(self, view: Any, W: Array, poses: Array) -> Array | None:
        """The features' residuals (n, m) of a map's drive frames (``W``: their concatenated
        features), or None when fewer than :meth:`_min_frames` of them are finite."""
        if len(poses) < self._min_frames():
            return None
        d = view.localizer
        e = d._residuals(d.regressor_, view.select(W), poses)["features"]
        return e if np.all(np.isfinite(e), axis=1).sum() >= self._min_frames() else None

    def _pooled_residuals(self, W: Array, poses: Array, owner: Array) -> dict[str, Array]:
        """Body-frame "pose" and "representation" residuals (n, 3) of the drive's frames,
        each from the map that measures it (``owner`` (n,), from :meth:`owners`: the
        district of its true pose; NaN rows out of its domain)."""
        out = {k: np.full((len(poses), 3), np.nan) for k in ("pose", "representation")}
        for k, view in enumerate(self._views):
            rows = owner == k
            if not rows.any():
                continue
            d = view.localizer
            res = d._residuals(d.regressor_, view.select(W[rows]), poses[rows])
            for name, rows_out in out.items():
                rows_out[rows] = res[name]
        return out

    def calibrate(self, motion_model: Any, images: ArrayLike, poses: ArrayLike,
                  controls: ArrayLike, measurements: tuple[str, ...] = MEASUREMENTS,
                  gate_probability: float | None = 0.997) -> Any:
        """Consistency of the hand-over filter on a recorded drive (as
        :meth:`AppearanceLocalizer.calibrate`); sets ``consistency_[measurement]``."""
        self.check_ready()
        images, poses, controls = AppearanceLocalizer._check_drive(images, poses, controls)
        W = self.transform(images)
        start = self.districts_[self.district_of(poses[0])]
        self.consistency_.update(calibrate_consistency(
            self, motion_model, W, poses, controls, measurements, gate_probability,
            start.noise_["pose"]))
        self.quality_ = {}
        return self
