"""Consistency calibration: run the belief over a recorded drive and inflate Q, R and P0.

For each measurement model, :class:`~localization.filtering.belief.BeliefFilter` runs over
the drive from its true start pose; Q, R and P0 are inflated per body component (along,
cross, heading) by ``alpha`` until the filter's covariance matches its errors
(:func:`~localization.filtering.measurement_noise.consistency_inflation`). A free function
that takes the localizer, so the belief does not import the localizer.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from localization.filtering.belief import BeliefFilter
from localization.filtering.localizer_protocol import Localizer
from localization.filtering.measurement_noise import consistency_inflation, inflate
from localization.geometry import Array, body_to_world

__all__ = ["calibrate_consistency"]


def calibrate_consistency(localizer: Localizer, motion_model: Any, W: Array, poses: Array,
                          controls: Array, measurements: tuple[str, ...],
                          gate_probability: float | None, initial_noise: Array,
                          ) -> dict[str, NDArray[np.float64]]:
    """Per-measurement inflation ``alpha`` (3,) that makes the belief consistent on a drive.

    Parameters
    ----------
    localizer : Localizer
        Fitted, with its noise model; ``localizer.consistency(m)`` is the starting point.
    motion_model : object
        F (the env's ``motion_model``).
    W : (n + 1, m) features of the drive's frames, in time order.
    poses : (n + 1, 3) true poses.
    controls : (n, 2) commanded controls.
    measurements : the measurement models to calibrate.
    gate_probability : float or None
        The belief's NIS gate.
    initial_noise : (3, 3)
        Body-frame covariance of the initial belief (inflated by ``alpha`` too).

    Returns
    -------
    dict
        ``{measurement: alpha}``.
    """
    out = {}
    for m in measurements:
        def run(alpha: Array, m: str = m) -> tuple[Array, Array]:
            belief = BeliefFilter(localizer, motion_model, m, gate_probability, None, alpha)
            P0 = body_to_world(inflate(initial_noise, alpha), poses[0, 2])
            means, covs, _ = belief.run(W, controls, poses[0], P0)
            return means, covs

        out[m] = consistency_inflation(run, poses, start=localizer.consistency(m))
    return out
