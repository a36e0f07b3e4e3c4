"""DistrictLocalizer: one appearance localizer per overlapping district of a large city.

One GSE embedding of a whole 60 m street network folds: on tuning city 53 (48000 street
images) psi*'s median error was 10.1 m, where a localizer fitted on one quadrant of the same
images reached 0.32 m (docs/benchmarks.md §10). A city is therefore cut into a grid of
districts (``grid`` cells of the training poses' bounding box); each district's
:class:`~localization.localizer.AppearanceLocalizer` (its own features and GSE maps) is
fitted on the images within ``overlap`` metres of its cell, so near a cell's edge the next
district's maps hold too.

The features of an image are those of every district side by side (``transform``: n x
(K m)). A filter hands over between districts by the belief: :meth:`DistrictLocalizer.local`
returns the district whose cell holds the pose (a :class:`District`: the
:class:`~localization.filtering.localizer_protocol.Localizer` interface on its block of the features),
and :class:`~localization.filtering.belief.BeliefFilter` measures each image with the
district at its prior mean. Without a pose (the first image, a restart) :meth:`initial_belief`
asks every district and keeps the answer that lies in its own district and whose image lies
closest to that district's feature manifold (the novelty ``|w - g(r*(w))|`` relative to the
district's median on its training images).

The particle belief weighs each particle by its own district's maps
(:mod:`localization.filtering.district_particles`); the EKF's divergence detection refuses a
district localizer (docs/method.md §12.1).

Noise (:meth:`DistrictLocalizer.fit_noise`): Q and the control gains from the drive; R of
the pose-like models ("pose", "representation": body-frame pose errors, comparable between
districts) pooled over the drive's frames, each measured by the district of its true pose;
the features' R per district from the drive's frames in its region (at least
``max(5 m, 200)`` finite residuals), else the district's in-sample training residuals (a
``RuntimeWarning`` names those districts). Consistency is calibrated on the whole hand-over filter.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from sklearn.exceptions import NotFittedError

from localization._district_maps import District, transform_maps
from localization._districts_io import load_districts, save_districts
from localization._districts_noise import DistrictNoiseMixin, inside, provisional_noise
from localization._localizer_noise import check_data
from localization._validation import check_array, check_int, check_real
from localization.familiarity import novelty_scale
from localization.geometry import Array, body_to_world
from localization.gse.graph import DisconnectedGraphError
from localization.gse.inverse import refine_poses, verify_poses
from localization.localizer import AppearanceLocalizer
from localization.turned_views import check_turn_camera, turned_prediction

__all__ = ["District", "DistrictLocalizer", "district_cells", "transform_maps"]


def district_cells(poses: ArrayLike, grid: tuple[int, int]) -> Array:
    """Cells (K, 4) ``[x0, y0, x1, y1]`` of a ``grid`` (nx, ny) split of the poses' bounding
    box, row by row (y), K = nx * ny."""
    xy = np.asarray(poses, dtype=np.float64)[:, :2]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    xs = np.linspace(lo[0], hi[0], grid[0] + 1)
    ys = np.linspace(lo[1], hi[1], grid[1] + 1)
    return np.array([[xs[i], ys[j], xs[i + 1], ys[j + 1]]
                     for j in range(grid[1]) for i in range(grid[0])])


class DistrictLocalizer(DistrictNoiseMixin):
    """Localize a camera in a large city with one :class:`AppearanceLocalizer` per district.

    Parameters
    ----------
    grid : (int, int)
        Districts along x and y (cells of the training poses' bounding box).
    overlap : float
        Metres around each cell whose images its district is fitted on too (the hand-over
        zone; at least the belief's error plus a step's travel).
    localizer_params : dict, optional
        Keyword arguments of each district's :class:`AppearanceLocalizer` (default
        ``noise_folds=0``: the noise comes from :meth:`fit_noise`).

    Attributes
    ----------
    districts_ : list of AppearanceLocalizer
        One per cell, fitted on the images of its region (cell + ``overlap``).
    cells_ : ndarray (K, 4)
        ``[x0, y0, x1, y1]`` of each district's cell.
    n_features_ : int
        Features per district (m); :meth:`transform` returns K m.
    train_index_ : list of ndarray
        The training images (indices) each district was fitted on: those within ``overlap``
        of its cell, less a few views cut off from the rest of its neighbourhood graph (at
        most the localizer's ``max_dropped``, 2 % by default).
    n_train_ : ndarray (K,)
        Training images per district.
    novelty_scale_ : ndarray (K,)
        Median novelty of each district's training images (500 evenly spaced,
        :func:`~localization.familiarity.novelty_scale`: the same unit as
        :class:`~localization.familiarity.Familiarity`'s; the unit of
        :meth:`initial_belief`'s choice).
    consistency_ : dict of str -> ndarray (3,)
    control_gain_, process_noise_body_ :
        From :meth:`fit_noise`, shared by the districts.
    camera_, image_size_, city_ :
        As the districts'.
    quality_ : dict
    """

    def __init__(self, grid: tuple[int, int] = (3, 3), overlap: float = 4.0,
                 localizer_params: dict[str, Any] | None = None) -> None:
        self.grid = grid
        self.overlap = overlap
        self.localizer_params = localizer_params

    # ------------------------------------------------------------------ fit
    def _check_params(self) -> tuple[int, int]:
        if not isinstance(self.grid, (tuple, list)) or len(self.grid) != 2:
            raise ValueError(f"grid must be a pair (nx, ny) of district counts, got {self.grid!r}")
        grid = (check_int(self.grid[0], "grid[0]", low=1), check_int(self.grid[1], "grid[1]", low=1))
        check_real(self.overlap, "overlap", low=0.0)
        if self.localizer_params is not None and not isinstance(self.localizer_params, dict):
            raise TypeError(f"localizer_params must be a dict, got "
                            f"{type(self.localizer_params).__name__}")
        return grid

    def fit(self, images: ArrayLike, poses: ArrayLike, *, camera: str | None = None,
            city: dict[str, Any] | None = None, progress: bool = False) -> DistrictLocalizer:
        """Fit each district's localizer on the images of its region.

        Parameters
        ----------
        images : ndarray (n, H, W, 3) uint8
        poses : ndarray (n, 3)
        camera, city :
            As :meth:`AppearanceLocalizer.fit`.
        progress : bool
            A progress bar over the districts.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            If a district's region holds too few images to fit (fewer districts or more
            overlap, or more images).
        """
        grid = self._check_params()
        images, poses = check_data(images, poses)
        self.cells_ = district_cells(poses, grid)
        groups = [np.flatnonzero(inside(poses[:, :2], cell, float(self.overlap)))
                  for cell in self.cells_]
        self._fit_maps(groups, images, poses, camera, city, "districts" if progress else None)
        return self

    def _fit_maps(self, groups: list[Array], images: Any, poses: Array, camera: str | None,
                  city: dict[str, Any] | None, progress: str | None) -> None:
        """One map per group of training images (indices; :meth:`_fit_district`), then the
        attributes the maps share; ``progress``: the progress bar's name (None: no bar)."""
        params = {"noise_folds": 0, **(self.localizer_params or {})}
        self.districts_, self.train_index_, scales = [], [], []
        bar: Any = range(len(groups))
        if progress is not None:
            from tqdm import tqdm
            bar = tqdm(bar, desc=progress, unit="map")
        for k in bar:
            loc, keep = self._fit_district(k, images, poses, groups[k], camera, city, params)
            self.districts_.append(loc)
            self.train_index_.append(keep)
            scales.append(novelty_scale(loc.regressor_))
        self._finish_fit(poses, scales)

    def _finish_fit(self, poses: Array, scales: list[float]) -> None:
        """The fitted attributes shared by the maps, after ``districts_`` and
        ``train_index_``."""
        self.n_train_ = np.array([len(i) for i in self.train_index_])
        self.novelty_scale_ = np.array(scales)
        self.n_features_ = int(self.districts_[0].regressor_.n_features_in_)
        self._poses_mean = np.array([*poses[:, :2].mean(axis=0), 0.0])
        self._poses_cov = np.diag([*poses[:, :2].var(axis=0), np.pi ** 2 / 3.0])
        self.consistency_: dict[str, Array] = {}
        self.quality_: dict[str, float] = {}
        self.control_gain_ = np.ones(2)
        self.process_noise_body_: Array | None = None
        self._set_views()

    def _set_views(self) -> None:
        self._views = [District(self, k) for k in range(len(self.districts_))]

    def get_params(self) -> dict[str, Any]:
        """Constructor arguments (JSON-friendly)."""
        return {"grid": list(self.grid), "overlap": float(self.overlap),
                "localizer_params": self.localizer_params}

    def save(self, path: str | Path) -> None:
        """Save to one ``.npz`` (no pickle): the settings as JSON, each district's own
        localizer file inside. The parent folder is created if missing."""
        self._check_fitted()
        save_districts(self, path)

    @classmethod
    def load(cls, path: str | Path) -> DistrictLocalizer:
        """Load a file written by :meth:`save` (FileNotFoundError if there is none;
        ValueError naming the file if it is corrupted); ``localization.load_localizer``
        loads either kind."""
        return load_districts(cls, path)

    @staticmethod
    def _fit_district(k: int, images: Any, poses: Array, index: Array, camera: str | None,
                      city: dict[str, Any] | None, params: dict[str, Any]
                      ) -> tuple[AppearanceLocalizer, Array]:
        """District k's localizer on the training images ``index``, and the indices it kept:
        a few views whose neighbourhood graph is cut off from the rest (at most the
        localizer's ``max_dropped``) are dropped. Without a K-fold noise model it gets a provisional one
        from its training residuals."""
        try:
            loc = AppearanceLocalizer(**params).fit(
                images[index], poses[index], camera=camera, city=city)
        except DisconnectedGraphError as err:
            raise ValueError(f"district {k} ({len(index)} training images): {err}; use fewer "
                             "districts or more overlap") from err
        except ValueError as err:  # e.g. too few images in the district
            raise ValueError(f"district {k} ({len(index)} training images): {err}; use "
                             "fewer districts, more overlap or more images") from err
        index = np.delete(index, loc.dropped_)
        provisional_noise(loc, images[index], poses[index], k)
        return loc, index

    def _check_fitted(self) -> None:
        if not hasattr(self, "districts_"):
            raise NotFittedError("this DistrictLocalizer is not fitted yet: call fit() first")

    # ---------------------------------------------------------- features
    @property
    def camera_(self) -> str | None:
        self._check_fitted()
        return self.districts_[0].camera_

    @property
    def image_size_(self) -> tuple[int, int]:
        self._check_fitted()
        return self.districts_[0].image_size_

    @property
    def city_(self) -> dict[str, Any] | None:
        self._check_fitted()
        return self.districts_[0].city_

    @property
    def noise_(self) -> dict[str, Array]:
        """The first district's R (the shapes a wrapper asks about)."""
        self._check_fitted()
        return self.districts_[0].noise_

    def check_city(self, city: dict[str, Any] | None, *, allow_other_city: bool = False) -> None:
        """As :meth:`AppearanceLocalizer.check_city`."""
        self._check_fitted()
        self.districts_[0].check_city(city, allow_other_city=allow_other_city)

    def transform(self, images: ArrayLike) -> Array:
        """Features of every district side by side, shape (n, K m) (:func:`transform_maps`)."""
        self._check_fitted()
        return np.concatenate(transform_maps(self.districts_, images), axis=1)

    def _check_w(self, w: ArrayLike) -> Array:
        w = check_array(w, "w").reshape(-1)
        size = len(self.districts_) * self.n_features_
        if w.shape != (size,):
            raise ValueError(f"w must be the concatenated features of the {len(self.districts_)} "
                             f"districts, shape ({size},), got {w.shape}")
        return w

    # ------------------------------------------------------ belief interface
    def district_of(self, pose: ArrayLike) -> int:
        """Index of the district whose cell holds ``pose`` (the nearest cell outside them)."""
        return int(self.districts_of(np.asarray(pose, dtype=np.float64).reshape(-1)[:3])[0])

    def districts_of(self, poses: ArrayLike) -> Array:
        """:meth:`district_of` of many poses (n, 3): indices (n,)."""
        self._check_fitted()
        xy = np.asarray(poses, dtype=np.float64).reshape(-1, 3)[:, :2]
        c = self.cells_
        dx = np.maximum(np.maximum(c[None, :, 0] - xy[:, :1], xy[:, :1] - c[None, :, 2]), 0.0)
        dy = np.maximum(np.maximum(c[None, :, 1] - xy[:, 1:], xy[:, 1:] - c[None, :, 3]), 0.0)
        return np.argmin(np.hypot(dx, dy), axis=1)

    @property
    def views_(self) -> list[District]:
        """Every district's :class:`District` (its Localizer on its block of w)."""
        self._check_fitted()
        return self._views

    def local(self, pose: ArrayLike, w: ArrayLike | None = None) -> District:
        """The district in charge at ``pose`` (the filter measures the image ``w`` with it;
        a district does not depend on the image)."""
        return self._views[self.district_of(pose)]

    def owners(self, poses: ArrayLike, W: ArrayLike) -> Array:
        """The district that measures each frame (n,): the one whose cell holds its pose
        (n, 3). ``W``, the frames' features (n, K m) or one image's (K m,) for every pose,
        is not needed here (an :class:`~localization.experiences.ExperienceLocalizer`
        chooses by it)."""
        return self.districts_of(poses)

    def _holds(self, k: int, x: Array) -> bool:
        """Whether district k's psi* ``x`` (3,) lies in its own region."""
        return bool(inside(x[None, :2], self.cells_[k], float(self.overlap))[0])

    def candidates(self, w: Array) -> list[tuple[float, int, Array]]:
        """(relative novelty, district, psi*) of every district whose psi*(w) lies in its own
        region, least novel first (``w``: the concatenated features)."""
        out = []
        for k, view in enumerate(self._views):
            wk = view.select(w)
            x = view.localizer.measure(wk, "pose")
            if not np.all(np.isfinite(x)):
                continue
            if not self._holds(k, x):
                continue
            u = float(view.localizer.regressor_.novelty(wk[None])[0])
            if np.isfinite(u):
                out.append((u / self.novelty_scale_[k], k, x))
        return sorted(out, key=lambda c: c[0])

    def measure(self, w: ArrayLike, measurement: str) -> Array:
        """Without a pose only the pose can be measured: psi* of the district chosen as in
        :meth:`initial_belief` (NaN when no district's maps hold); the other models depend on
        the district: use ``local(pose).measure``."""
        self._check_fitted()
        if measurement != "pose":
            raise ValueError(f"a DistrictLocalizer measures {measurement!r} with the district "
                             "at a pose: use local(pose).measure(w, measurement)")
        found = self.candidates(self._check_w(w))
        return found[0][2] if found else np.full(3, np.nan)

    def initial_belief(self, w: ArrayLike) -> tuple[Array, Array]:
        """Belief from one image: the chosen district's psi*(w) and initial covariance (the
        mean is NaN when no district's maps hold)."""
        x0, P0, _ = self.initial_candidate(w)
        return x0, P0

    def initial_candidate(self, w: ArrayLike) -> tuple[Array, Array, float]:
        """:meth:`initial_belief` (mean (3,), covariance (3, 3)) and how familiar the image
        is: its relative novelty under the chosen district (its novelty over the median of
        that district's training images; inf when no district's maps hold). The belief
        filter's ``familiar_novelty`` restarts only from familiar images
        (:mod:`~localization.filtering.familiar_start`)."""
        self.check_ready()
        found = self.candidates(self._check_w(w))
        if not found:
            return np.full(3, np.nan), np.array(self._poses_cov), float("inf")
        u, k, x = found[0]
        return x, body_to_world(self.districts_[k].initial_noise_, float(x[2])), float(u)

    def prior(self) -> tuple[Array, Array]:
        """Mean and covariance of all training poses (a know-nothing belief)."""
        self._check_fitted()
        return self._poses_mean.copy(), self._poses_cov.copy()

    def consistency(self, measurement: str) -> Array:
        """Calibrated body-frame inflation (3,) of the hand-over filter's model."""
        return np.asarray(getattr(self, "consistency_", {}).get(measurement, np.ones(3)))

    def measurement_model(self, measurement: str, alpha: ArrayLike | None = None,
                          **options: Any) -> Any:
        """The model of the district at a pose: use ``local(pose).measurement_model``."""
        raise ValueError("a DistrictLocalizer's measurement model depends on the district: "
                         "use local(pose).measurement_model(...)")

    def process_noise(self, pose: ArrayLike, alpha: ArrayLike | None = None) -> Array:
        """Q(x) (3, 3) at ``pose`` (shared by the districts)."""
        return self.local(pose).process_noise(pose, alpha)

    def check_ready(self) -> None:
        """NotFittedError unless fitted with a noise model (:meth:`fit_noise`)."""
        self._check_fitted()
        for d in self.districts_:
            d.check_ready()

    def predict(self, images: ArrayLike, refine: int = 0, verify: int = 0,
                verify_margin: float = 3.0, turns: int = 0) -> Array:
        """psi* (n, 3) of images, each by the district chosen as in :meth:`initial_belief`
        (NaN rows where no district's maps hold); ``verify`` > 0, ``refine`` > 0: checked
        against that many retrieved training poses, then refined by that many Gauss-Newton
        steps, with the chosen district's maps; ``turns`` > 0: positions the median over
        turned views (all as :meth:`AppearanceLocalizer.predict`)."""
        refine = check_int(refine, "refine", low=0)
        verify = check_int(verify, "verify", low=0)
        verify_margin = check_real(verify_margin, "verify_margin", low=1.0)
        turns = check_int(turns, "turns", low=0)
        self._check_fitted()
        if turns:
            check_turn_camera(self.camera_)
        return turned_prediction(lambda views: self._predict_views(views, refine, verify,
                                                                   verify_margin),
                                 self.districts_[0].check_images(images), turns)

    def _predict_views(self, images: ArrayLike, refine: int, verify: int,
                       verify_margin: float) -> Array:
        """psi* (n, 3) of images by their districts, verified and refined (:meth:`predict`)."""
        out, whiteners = [], {}  # each district's whitener, once
        for w in self.transform(images):
            found = self.candidates(w)
            if not found:
                out.append(np.full(3, np.nan))
                continue
            _, k, x = found[0]
            if refine or verify:
                loc, wk = self.districts_[k], self._views[k].select(w)[None]
                theta, L = loc.to_model(x), whiteners.setdefault(k, loc.feature_whitener())
                if verify:
                    theta, _ = verify_poses(loc.regressor_, wk, theta, L, verify, verify_margin)
                if refine:
                    theta = refine_poses(loc.regressor_, wk, theta, L, refine)
                x = loc.from_model(theta)[0]
            out.append(x)
        return np.array(out)
