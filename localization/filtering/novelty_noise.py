"""Measurement noise that grows with the image's novelty: R scaled by how far the image lies
off the map's feature manifold.

One R (global, or R(theta, w) from K-fold residuals) describes the images it was estimated
from: the frames of the noise drive, in the map's own light. An image unlike them (another
light, sensor noise, an occluder) lies farther from the manifold of the training features,
and to first order its error in ``r*(w)`` grows with that distance, so its variance grows with
the distance's square::

    u(w)  = |w - g_u(r*(w))|                        (novelty, reduce-then-recover)
    u_0   = median of u over the noise drive's frames  (``localizer.novelty_ref_``)
    s(w)  = min(max(1, u(w) / u_0) ** power, max_scale),     R_k = s(w_k) R

``s >= 1``: a frame as familiar as the drive's typical one keeps R; only more novel frames
lose weight. The EKF's gate keeps the unscaled R
(:class:`~localization.filtering.adaptive_noise.ScaledMeasurement`), so the scaling never
lets in a frame the gate would reject. Probed on tuning cities 13-14 (daylight map, route
drives under the appearance presets): psi*'s normalised squared error grew about as the
relative novelty to the power 1.6-1.7 from daylight to night (docs/benchmarks.md §9
"Stop 77").
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_real, check_settings
from localization.filtering.adaptive_noise import ScaledMeasurement

__all__ = ["NoveltyNoise", "check_novelty_ref", "novelty_noise"]


class NoveltyNoise:
    """The scale ``s(w)`` of R (see the module docstring).

    Parameters
    ----------
    power : float
        Exponent of the novelty ratio (> 0; 2: the variance of a first-order error).
    max_scale : float
        Largest scale (>= 1).

    Attributes
    ----------
    scale : float
        The scale of the last image (1 before any).
    """

    def __init__(self, power: float = 2.0, max_scale: float = 100.0) -> None:
        self.power = float(check_real(power, "power", low=0.0, low_open=True))
        self.max_scale = float(check_real(max_scale, "max_scale", low=1.0))
        self.scale = 1.0

    def scale_of(self, localizer: Any, w: ArrayLike) -> float:
        """``s(w)`` under ``localizer``'s map (NaN features, or out of the domain: 1, the
        filter finds no measurement there anyway)."""
        u = localizer.regressor_.novelty(np.asarray(w, dtype=np.float64).reshape(1, -1))[0]
        if not np.isfinite(u):
            return 1.0
        ratio = max(1.0, float(u) / check_novelty_ref(localizer))
        return float(min(ratio ** self.power, self.max_scale))

    def wrap(self, model: Any, localizer: Any, w: ArrayLike) -> ScaledMeasurement:
        """``model`` with R scaled by ``s(w)`` (kept in :attr:`scale`)."""
        self.scale = self.scale_of(localizer, w)
        return ScaledMeasurement(model, self.scale)


def check_novelty_ref(localizer: Any) -> float:
    """``localizer.novelty_ref_`` (> 0); ValueError naming the option when the localizer has
    none (its R did not come from a recorded drive: call ``fit_noise``)."""
    ref = getattr(localizer, "novelty_ref_", None)
    if ref is None or not np.isfinite(ref) or ref <= 0:
        raise ValueError("novelty_noise needs the novelty of the frames R was estimated from "
                         f"(novelty_ref_); {type(localizer).__name__} has none: fit its noise "
                         "on a recorded drive with fit_noise (a saved file from before it has "
                         "none either)")
    return float(ref)


def novelty_noise(option: bool | dict[str, Any] | NoveltyNoise, localizer: Any
                  ) -> NoveltyNoise | None:
    """The :class:`NoveltyNoise` a ``novelty_noise`` option asks for (None: off;
    :func:`~localization._validation.check_settings`), checked against ``localizer``: one
    map with ``novelty_ref_`` (TypeError for a localizer of several maps, ValueError without
    the reference)."""
    model = check_settings(option, "novelty_noise", NoveltyNoise)
    if model is None:
        return None
    if callable(getattr(localizer, "local", None)):
        raise TypeError("novelty_noise needs a localizer of one map (an AppearanceLocalizer); "
                        f"{type(localizer).__name__} has several (use False)")
    check_novelty_ref(localizer)
    return model
