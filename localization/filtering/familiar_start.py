"""Familiar starts: a belief placed from one image rests on it only if the image looks like
the maps' training images (docs/method.md §13.5).

One image's psi* is a look-alike place far more often when the image is unlike every training
image. The localizer rates that with the image's relative novelty ``u``: the novelty
``|w - g(r*(w))|`` of its features under the map that gives psi*, over the median of that
map's training images (:meth:`~localization.districts.DistrictLocalizer.initial_candidate`).
On tuning city 53's street tours (3000 frames of six tours, the 60 m city's district maps) the
first psi* was more than 3 m off on 0.0 % of the frames with ``u < 2.5``, 0.6-0.7 % at 2.5-4,
5.5 % at 4-6, 22 % at 6-10 and on half of those above 10 (``u < 3``: 75 % of the frames).

With ``BeliefFilter(familiar_novelty=u_max)`` an image is *familiar* when ``u <= u_max``:

- The first image places the belief even when it is unfamiliar (its psi* is usually still
  the best guess there is), but the start is *unverified*: the first familiar image decides.
  If its psi* ``x0`` (covariance ``P0``, the localizer's initial noise) lies inside the gate
  of the belief ``x``, ``P``::

      d^2 = (x0 - x)^T (P + P0)^-1 (x0 - x) <= chi2_3(gate_probability)

  the start is verified; otherwise the belief restarts at ``x0`` ("relocalized", on trial).
- Every other restart from an image needs a familiar one: after ``relocalize_after`` misses
  the belief waits for one (each further miss tries again); a trial that failed with nothing
  to come back to restarts at the current image only if it is familiar, else the belief stays
  where the trial left it (and restarts after ``relocalize_after`` misses).

On city 53 a first image 8.3 m off (``u = 13``), whose look-alike the next 34 images agreed
with, was replaced at the fifth image; the later restarts of a belief coasting through views
off the maps no longer jumped to look-alikes 7-40 m away (docs/benchmarks.md §10 "Stop 61").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization._validation import check_real
from localization.filtering.ekf import gate_threshold
from localization.geometry import Array, wrap_angle

__all__ = ["AGREE_PROBABILITY", "FamiliarStartMixin", "ImageStart", "check_familiar_novelty",
           "start_agrees"]

#: the agreement gate's probability when the belief filter has no NIS gate
AGREE_PROBABILITY = 0.997

#: psi*(w) (3,), its covariance (3, 3) and whether the image is familiar
ImageStart = tuple[Array, Array, bool]


def check_familiar_novelty(familiar_novelty: object, localizer: Any) -> float | None:
    """``familiar_novelty``: None, or a relative novelty > 0 with a localizer that rates
    images (``initial_candidate``, e.g. a DistrictLocalizer)."""
    if familiar_novelty is None:
        return None
    value = check_real(familiar_novelty, "familiar_novelty", low=0.0, low_open=True)
    if not callable(getattr(localizer, "initial_candidate", None)):
        raise TypeError("familiar_novelty needs a localizer that rates how familiar an image "
                         "is (initial_candidate, e.g. a DistrictLocalizer); "
                         f"{type(localizer).__name__} has none (use None)")
    return float(value)


def start_agrees(x: Array, P: Array, x0: Array, P0: Array,
                 gate_probability: float | None) -> bool:
    """Whether psi* ``x0`` (3,) with covariance ``P0`` (3, 3) lies inside the gate of the
    belief ``x`` (3,), ``P`` (3, 3): ``d^2 <= chi2_3(gate_probability)`` (see the module
    docstring; :data:`AGREE_PROBABILITY` when None)."""
    d = np.asarray(x0, dtype=np.float64) - np.asarray(x, dtype=np.float64)
    d[2] = wrap_angle(d[2])
    d2 = float(d @ np.linalg.solve(np.asarray(P) + np.asarray(P0), d))
    return d2 <= gate_threshold(gate_probability or AGREE_PROBABILITY, 3)


class FamiliarStartMixin:
    """The belief filter's starts from images with ``familiar_novelty`` (module docstring).

    The host class provides ``localizer``, ``ekf``, ``gate_probability``, ``belief_status``,
    ``familiar_novelty``, ``_unverified`` and ``_from_image(w, first, start)``."""

    localizer: Any
    ekf: Any
    gate_probability: float | None
    belief_status: str
    familiar_novelty: float | None
    _unverified: bool
    _from_image: Any

    def _image_start(self, w: Array) -> ImageStart:
        """psi*(w), its covariance and whether the image is familiar (always without
        ``familiar_novelty``)."""
        if self.familiar_novelty is None:
            x0, P0 = self.localizer.initial_belief(w)
            return x0, P0, True
        x0, P0, u = self.localizer.initial_candidate(w)
        return x0, P0, bool(u <= self.familiar_novelty)

    def _verify_start(self, w: Array, status: str) -> str:
        """An unverified start meets image ``w``: if it is familiar, its psi* verifies the
        belief (inside the gate) or restarts it there ("relocalized")."""
        start = self._image_start(w)
        x0, P0, familiar = start
        if not (familiar and np.all(np.isfinite(x0))):
            return status
        if start_agrees(self.ekf.x, self.ekf.P, x0, P0, self.gate_probability):
            self._unverified = False
            return status
        self._from_image(w, start=start)
        self.belief_status = "relocalizing"
        return "relocalized"
