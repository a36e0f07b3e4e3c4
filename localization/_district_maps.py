"""The maps of a multi-map localizer (:class:`~localization.districts.DistrictLocalizer` and
:class:`~localization.experiences.ExperienceLocalizer`): :class:`District`, one map on its block
of the concatenated features, and :func:`transform_maps`, every map's features with a feature
network the maps share run once."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array
from localization.localizer import AppearanceLocalizer

__all__ = ["District", "transform_maps"]


def transform_maps(maps: list[AppearanceLocalizer], images: ArrayLike) -> list[Array]:
    """Each map's features of ``images`` ((n, m) each), running a feature network the maps
    share (equal :meth:`~AppearanceLocalizer.stage_key`, e.g. one SmallCNN under per-map
    PCAs) once: ``[m.transform(images) for m in maps]``, K times cheaper."""
    embedded: dict[Any, Array] = {}
    out = []
    for m in maps:
        key = m.stage_key()
        if key is None:
            out.append(m.transform(images))
            continue
        if key not in embedded:
            embedded[key] = m.embed(images)
        out.append(m.head(embedded[key]))
    return out


class District:
    """The :class:`~localization.filtering.localizer_protocol.Localizer` of district ``index`` of a
    :class:`DistrictLocalizer`: its localizer on its block of the concatenated features w
    (K m,), with the parent's consistency."""

    def __init__(self, parent: Any, index: int) -> None:
        self.parent, self.index = parent, index
        self.localizer: AppearanceLocalizer = parent.districts_[index]
        m = parent.n_features_
        self._block = slice(index * m, (index + 1) * m)

    @property
    def control_gain_(self) -> Array:
        """The parent's calibrated control gains (shared by the districts)."""
        return self.parent.control_gain_

    def select(self, w: ArrayLike) -> Array:
        """This district's features (m,) out of the concatenated w (K m,)."""
        return np.asarray(w, dtype=np.float64)[..., self._block]

    def measure(self, w: ArrayLike, measurement: str) -> Array:
        """The district's measurement of the named model from the concatenated w."""
        return self.localizer.measure(self.select(w), measurement)

    def measurement_model(self, measurement: str, alpha: ArrayLike | None = None,
                          **options: Any) -> Any:
        """The district's model; one that observes the image (heteroscedastic R) is given
        this district's block of w."""
        alpha = self.consistency(measurement) if alpha is None else alpha
        model = self.localizer.measurement_model(measurement, alpha=alpha, **options)
        observe = getattr(model, "observe", None)
        if callable(observe):
            model.observe = lambda w: observe(self.select(w))
        return model

    def consistency(self, measurement: str) -> Array:
        return self.parent.consistency(measurement)

    def process_noise(self, pose: ArrayLike, alpha: ArrayLike | None = None) -> Array:
        return self.localizer.process_noise(pose, alpha)

    def initial_belief(self, w: ArrayLike) -> tuple[Array, Array]:
        return self.localizer.initial_belief(self.select(w))

    def prior(self) -> tuple[Array, Array]:
        return self.parent.prior()
