"""ExperienceLocalizer: one appearance localizer per look of the same streets.

Condition-invariant features carry a map made in daylight to overcast, fog and camera
effects, but not to the dark: at night the far facades are gone and the near ones lit by the
robot's own light, and no feature extractor can bring back what the image does not show.
On tuning city 13 a daylight map read 37 % of night street images beyond 1 m; a map of the
same poses rendered in one jittered night look read 2 % (and 48 % of daylight images:
docs/method.md §12). Experience-based navigation (Churchill and Newman, "Experience-based
navigation for long-term localisation", IJRR 2013) keeps one map per look and lets each
image choose.

An :class:`ExperienceLocalizer` holds one :class:`~localization.localizer.AppearanceLocalizer`
per *experience* (a label per training image, e.g. the look it was rendered in; typically
the same poses in every look). It is a :class:`~localization.districts.DistrictLocalizer`
whose maps all cover the whole city and are chosen by the image, not the pose:

- ``transform``: every experience's features side by side (n, K m).
- :meth:`ExperienceLocalizer.experience_of`: the experience whose feature manifold lies
  closest to the image, relative to its training images (the novelty
  ``|w - g(r*(w))|`` divided by the experience's median on its own training images, the
  DistrictLocalizer's unit); the belief filter measures each image with it
  (``local(x, w)``), and each particle is weighed by it.
- Noise: Q and the control gains from the drive, the pose-like R pooled over the frames
  each measured by its chosen experience, and each experience's features' R from the drive
  frames it was chosen for (its training residuals when fewer than ``max(5 m, 200)`` of
  them are finite).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._districts_noise import provisional_noise
from localization._localizer_noise import check_data
from localization.districts import District, DistrictLocalizer
from localization.geometry import Array
from localization.gse.graph import DisconnectedGraphError
from localization.localizer import AppearanceLocalizer

__all__ = ["ExperienceLocalizer", "check_labels"]


def check_labels(labels: ArrayLike, n: int) -> tuple[Array, list[str]]:
    """Experience index (n,) of each training image and the experiences' names (sorted).

    Raises
    ------
    ValueError
        If ``labels`` is not one label per image (shape (n,)), or holds fewer than two
        experiences.
    """
    arr = np.asarray(labels)
    if arr.ndim != 1 or len(arr) != n:
        raise ValueError(f"experiences must hold one label per training image, shape ({n},), "
                         f"got shape {arr.shape}")
    names, index = np.unique(arr.astype(str), return_inverse=True)
    if len(names) < 2:
        raise ValueError(f"experiences must name at least two looks, got {list(names)}: "
                         "with one, fit an AppearanceLocalizer")
    return index.ravel(), [str(name) for name in names]


class ExperienceLocalizer(DistrictLocalizer):
    """Localize a camera under changing appearance with one map per look (experience).

    Parameters
    ----------
    localizer_params : dict, optional
        Keyword arguments of each experience's :class:`AppearanceLocalizer` (default
        ``noise_folds=0``: the noise comes from :meth:`fit_noise`).

    Attributes
    ----------
    labels_ : list of str
        The experiences' names, in the order of ``districts_`` (the sorted labels).
    districts_ : list of AppearanceLocalizer
        One per experience, fitted on its images.
    train_index_ : list of ndarray
        The training images (indices) each experience was fitted on.
    n_train_, novelty_scale_, n_features_, consistency_, control_gain_,
    process_noise_body_, camera_, image_size_, city_, quality_ :
        As :class:`~localization.districts.DistrictLocalizer`'s.
    """

    FORMAT = "appearance-nav-experiences/1"

    def __init__(self, localizer_params: dict[str, Any] | None = None) -> None:
        self.localizer_params = localizer_params
        self.grid, self.overlap = (1, 1), 0.0  # one region, the whole city

    def fit(self, images: ArrayLike, poses: ArrayLike, *, experiences: ArrayLike | None = None,
            camera: str | None = None, city: dict[str, Any] | None = None,
            progress: bool = False) -> ExperienceLocalizer:
        """Fit each experience's localizer on its images.

        Parameters
        ----------
        images : ndarray (n, H, W, 3) uint8
        poses : ndarray (n, 3)
        experiences : array-like (n,)
            The experience (look) of each image, e.g. its conditions' name; at least two.
        camera, city :
            As :meth:`AppearanceLocalizer.fit`.
        progress : bool
            A progress bar over the experiences.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            If ``experiences`` is missing or malformed, or an experience's images are too
            few (or too alike) to fit.
        """
        self._check_params()
        images, poses = check_data(images, poses)
        if experiences is None:
            raise ValueError("experiences is required: the look (a label) of each image")
        index, self.labels_ = check_labels(experiences, len(poses))
        xy = poses[:, :2]
        self.cells_ = np.tile(np.r_[xy.min(axis=0), xy.max(axis=0)], (len(self.labels_), 1))
        groups = [np.flatnonzero(index == k) for k in range(len(self.labels_))]
        self._fit_maps(groups, images, poses, camera, city, "experiences" if progress else None)
        return self

    def _fit_district(self, k: int, images: Any, poses: Array, index: Array,  # type: ignore[override]
                      camera: str | None, city: dict[str, Any] | None,
                      params: dict[str, Any]) -> tuple[AppearanceLocalizer, Array]:
        """Experience k's localizer on the training images ``index`` and the indices it
        kept (as :meth:`DistrictLocalizer._fit_district`)."""
        try:
            loc = AppearanceLocalizer(**params).fit(images[index], poses[index], camera=camera,
                                                    city=city)
        except (DisconnectedGraphError, ValueError) as err:
            raise ValueError(f"experience {self.labels_[k]!r} ({len(index)} training images): "
                             f"{err}") from err
        index = np.delete(index, loc.dropped_)
        provisional_noise(loc, images[index], poses[index], k)
        return loc, index

    def get_params(self) -> dict[str, Any]:
        """Constructor arguments (JSON-friendly)."""
        return {"localizer_params": self.localizer_params}

    # ------------------------------------------------------ choosing a look
    def novelties(self, W: ArrayLike) -> Array:
        """Relative novelty (n, K) of features W (n, K m) or (K m,) under each experience:
        ``|w_k - g_k(r_k*(w_k))|`` over its training images' median; inf out of its
        domain."""
        self._check_fitted()
        W = np.asarray(W, dtype=np.float64)
        W = self._check_w(W)[None] if W.ndim == 1 else W
        if W.ndim != 2 or W.shape[1] != len(self._views) * self.n_features_:
            raise ValueError(f"W must hold the concatenated features of the "
                             f"{len(self._views)} experiences, shape (n, "
                             f"{len(self._views) * self.n_features_}), got {W.shape}")
        U = np.column_stack([
            view.localizer.regressor_.novelty(W[:, view._block]) / self.novelty_scale_[k]
            for k, view in enumerate(self._views)])
        return np.where(np.isfinite(U), U, np.inf)

    def experiences_of(self, W: ArrayLike) -> Array:
        """Index (n,) of the experience most like each image (the least relative novelty;
        the first experience when every map is out of its domain)."""
        U = self.novelties(W)
        return np.where(np.isfinite(U).any(axis=1), np.argmin(U, axis=1), 0)

    def experience_of(self, w: ArrayLike) -> int:
        """:meth:`experiences_of` of one image's features w (K m,); the last image's choice
        is kept, so the filter's calls for one image (its measurement, its particles' weights)
        choose once."""
        w = self._check_w(w)
        key = w.tobytes()
        if self._last_choice is not None and self._last_choice[0] == key:
            return self._last_choice[1]
        k = int(self.experiences_of(w[None])[0])
        self._last_choice = (key, k)
        return k

    # ------------------------------------------------------ belief interface
    def local(self, pose: ArrayLike, w: ArrayLike | None = None) -> District:
        """The experience that measures the image ``w`` (the first one without an image)."""
        self._check_fitted()
        return self._views[0 if w is None else self.experience_of(w)]

    def owners(self, poses: ArrayLike, W: ArrayLike) -> Array:
        """The experience that measures each frame (n,): chosen by its features W (n, K m),
        or for one image's w (K m,) the same for every pose (n, 3)."""
        n = len(np.asarray(poses, dtype=np.float64).reshape(-1, 3))
        W = np.asarray(W, dtype=np.float64)
        if W.ndim == 1:
            return np.full(n, self.experience_of(W))
        return self.experiences_of(W)

    def _holds(self, k: int, x: Array) -> bool:
        """Every experience maps the whole city."""
        return True

    def _region(self, k: int, poses: Array, owner: Array) -> Array:
        """The drive frames experience k was chosen for (its features' R)."""
        return owner == k

    def _set_views(self) -> None:
        super()._set_views()
        self._last_choice: tuple[bytes, int] | None = None
