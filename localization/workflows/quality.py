"""The quality report of a localizer fitted on a city: is its belief worth driving on?

:func:`~localization.workflows.tracking.fit_city_localizer` drives once more on the finished
belief (a held-out drive: not used by the fit, the noise model or the calibration) and keeps
the scores as ``localizer.quality_`` (saved with it):

- ``rmse`` / ``rmse_dead_reckoning`` / ``ratio``: position RMSE (m) of the belief and of F
  alone from the true start with the same controls, and their ratio (> 1: the images made
  it worse than not looking at all);
- ``accepted``: fraction of measurements the NIS gate accepted;
- ``nees_mean`` (3 for a consistent belief) and ``max_error`` (m);
- ``alpha_<model>_<component>``: the consistency calibration's inflation factors of Q, R
  and P0 (body frame: along, cross, heading); ``alpha_at_cap`` counts those that reached
  the calibration's bound ``alpha_cap`` (the filter could not be made consistent there).

:func:`warn_quality` raises a :class:`LocalizerQualityWarning` with the numbers when the
belief is worse than dead reckoning or a factor hit its cap (issue 12: a street-wide
localizer of 4000 images was 4-13x worse than dead reckoning, silently). Measured on city 0
(6000 route images, 1500-step drives, motion noise 0.05): the "features" model's along and
cross factors reach the bound 100 (its belief is 0.13 m off on average but its mean NEES is
13), so a default fit warns about that model, and only about it; "pose" and
"representation" calibrate to 1.2-4.6.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from localization.filtering.measurement_noise import MAX_INFLATION

__all__ = ["COMPONENTS", "TRACK_KEYS", "LocalizerQualityWarning", "quality_problems",
           "quality_report", "quality_table", "warn_quality"]

#: body-frame components of the inflation factors
COMPONENTS = ("along", "cross", "heading")
#: scores of the held-out drive (NaN when it was skipped)
TRACK_KEYS = ("steps", "rmse", "rmse_dead_reckoning", "ratio", "accepted", "nees_mean",
              "max_error")


class LocalizerQualityWarning(UserWarning):
    """A fitted localizer is worse than dead reckoning or its calibration hit a bound."""


def quality_report(metrics: Mapping[str, float] | None,
                   consistency: Mapping[str, ArrayLike],
                   max_alpha: float = MAX_INFLATION) -> dict[str, float]:
    """The quality report (a flat dict of floats) from a held-out drive and the calibration.

    Parameters
    ----------
    metrics : dict or None
        :func:`~localization.workflows.tracking.track_metrics` of the held-out drive; None:
        no drive (its keys are NaN).
    consistency : dict of str -> (3,)
        The localizer's ``consistency_`` (inflation factors per measurement model).
    max_alpha : float
        The calibration's upper bound.
    """
    out = {k: float(metrics[k]) if metrics is not None else math.nan for k in TRACK_KEYS}
    factors = []
    for model, alpha in consistency.items():
        alpha = np.asarray(alpha, dtype=np.float64).reshape(3)
        factors.append(alpha)
        out |= {f"alpha_{model}_{c}": float(a) for c, a in zip(COMPONENTS, alpha, strict=True)}
    all_factors = np.concatenate(factors) if factors else np.zeros(0)
    out["alpha_max"] = float(all_factors.max()) if factors else math.nan
    out["alpha_cap"] = float(max_alpha)
    out["alpha_at_cap"] = float(np.sum(all_factors >= max_alpha * (1.0 - 1e-9)))
    return out


def quality_problems(quality: Mapping[str, float], max_ratio: float = 1.0) -> list[str]:
    """What is wrong with a localizer by its report, one sentence each (empty: nothing)."""
    problems = []
    ratio = quality.get("ratio", math.nan)
    if math.isfinite(ratio) and ratio > max_ratio:
        problems.append(
            f"its belief is worse than dead reckoning on a held-out drive of "
            f"{quality['steps']:.0f} steps: position RMSE {quality['rmse']:.2f} m vs "
            f"{quality['rmse_dead_reckoning']:.2f} m ({ratio:.1f}x), {quality['accepted']:.0%} "
            f"of the measurements accepted, mean NEES {quality['nees_mean']:.1f} (3 if "
            f"consistent). More training images (n_train), a longer noise drive (n_drive) or "
            f"training lanes that cover where the robot drives usually help")
    cap = quality.get("alpha_cap", MAX_INFLATION)
    capped: dict[str, list[str]] = {}
    for k, v in quality.items():
        model, _, component = k[len("alpha_"):].rpartition("_")
        if k.startswith("alpha_") and component in COMPONENTS and v >= cap * (1.0 - 1e-9):
            capped.setdefault(model, []).append(component)
    for model, components in capped.items():
        problems.append(
            f"the consistency calibration of the {model!r} model hit its bound {cap:g} "
            f"({', '.join(components)}): a belief on that model stays over-confident; use "
            f"another measurement model")
    return problems


def warn_quality(quality: Mapping[str, float], max_ratio: float = 1.0,
                 stacklevel: int = 2) -> list[str]:
    """Warn (one :class:`LocalizerQualityWarning`) about :func:`quality_problems`; return
    them."""
    problems = quality_problems(quality, max_ratio)
    if problems:
        warnings.warn("fitted localizer: " + "; ".join(problems) + ".",
                      LocalizerQualityWarning, stacklevel=stacklevel + 1)
    return problems


def quality_table(quality: Mapping[str, float]) -> str:
    """The report as a two-column markdown table."""
    lines = ["| quality | value |", "|---|---:|"]
    lines += [f"| {k} | {v:.4g} |" for k, v in quality.items()]
    return "\n".join(lines) + "\n"
