"""Divergence detection for the EKF belief: notice that it is lost, and where it may be.

A single-hypothesis EKF that has lost the robot (kidnapped, or locked onto a look-alike
place) either gates every measurement or, worse, accepts aliased ones while confident. Two
windowed tests over the last ``window`` steps tell:

- **NIS test**: the mean of the window's NIS values (each capped at ``nis_cap``, so one
  corrupted image counts at most that much) above the upper end of its chi-square band,
  ``chi2_band(dim_z, n, nis_prob)[1]`` (:func:`~localization.filtering.ekf.chi2_band`);
- **psi* disagreement**: the share of the window's images whose pose regression psi*(w)
  is farther from the belief mean than ``disagree_distance`` metres plus 3 standard
  deviations of the belief (the largest of P's position block), or whose heading is off by
  more than ``disagree_heading`` plus 3 of P's heading deviations, is at least
  ``disagree_fraction``. (A metric distance, not a Mahalanobis one: psi*'s noise model
  counts its aliasing errors, which makes it metres wide on a street-wide map, and no
  single image could then ever disagree.)

Either test alone marks the belief "lost" (reported, nothing changed); both together, while
the filter also rejected at least ``min_rejected`` of the window's measurements,
re-initialise it from the image's proposals: the window's psi* values, each moved to the
present by the motion model F with the controls since, are clustered
(:func:`~localization.filtering._modes.find_modes`); when the largest cluster holds at
least ``min_support`` of them the belief restarts at its mean with the cluster's
covariance plus ``diag(restart_std**2)`` (not the plain second moment of psi*'s errors,
which counts its aliasing: so wide a restart let the next aliased measurement move the
belief metres). A single aliased image
therefore cannot move the belief; a kidnap is noticed in about ``window`` steps.

Off by default (``BeliefFilter(detect_divergence=False)``, the wrapper's
``filter_options={"detect_divergence": True}`` turns it on). ``appearance-nav bench --only
global`` (held-out cities 21-23, 120 kidnaps; docs/benchmarks.md §5): recovered within 30
steps 100 % (median 5) against 0 % for the EKF without it, but false restarts where psi*
stays aliased for several steps while the EKF is right make nominal tracking worse (RMSE
0.43 m against 0.065 m). Until that is fixed the EKF's nominal behaviour stays the default.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from localization._validation import check_int, check_real
from localization.filtering._modes import find_modes
from localization.filtering.ekf import chi2_band
from localization.filtering.particle_motion import predict_particles
from localization.geometry import Array, wrap_angle

__all__ = ["BELIEF_STATUSES", "DivergenceMonitor"]

#: What a belief says about itself (``info["belief_status"]`` of the wrappers):
#: "tracking" (consistent), "ambiguous" (several hypotheses, none dominant; particles only),
#: "lost" (the tests say the belief is wrong), "relocalizing" (just re-initialised, or
#: started with an unknown pose, and not yet confirmed by measurements).
BELIEF_STATUSES = ("tracking", "ambiguous", "lost", "relocalizing")


@dataclass
class Verdict:
    """One step's outcome: ``lost`` (either test fired), ``restart`` (both fired and the
    proposals agree: the pose (3,) to restart at, else None) and ``restart_cov`` (3, 3), the
    spread of the proposals that agree."""

    lost: bool
    restart: Array | None = None
    restart_cov: Array | None = None


class DivergenceMonitor:
    """Windowed NIS and psi*-disagreement tests (see the module docstring).

    Parameters
    ----------
    window : int
        Steps in each window (>= 2).
    nis_prob : float in (0, 1)
        Coverage of the NIS band.
    nis_cap : float
        Largest NIS value one step contributes (> 0).
    disagree_distance : float
        Metres (beyond 3 sigma of the belief) from which psi* disagrees.
    disagree_heading : float
        Radians (beyond 3 sigma of the belief) from which psi* disagrees.
    disagree_fraction : float in (0, 1]
        Share of the window's psi* values that must disagree.
    min_rejected : float in [0, 1]
        Share of the window's measurements the filter must have rejected (gated or out of
        domain) before a restart: on a weak map psi* is aliased for stretches of ten steps
        while the filter, still right, keeps accepting its measurements.
    min_support : float in (0, 1]
        Share of the window's proposals the restart cluster must hold.
    mode_radius : float
        Cluster radius (m; a radian of heading counts 2 m).
    restart_std : (float, float, float)
        Standard deviations (x, y, yaw) added to the cluster's spread at a restart.
    """

    def __init__(self, window: int = 8, nis_prob: float = 0.99, nis_cap: float = 30.0,
                 disagree_distance: float = 2.0, disagree_heading: float = 0.8,
                 disagree_fraction: float = 0.6, min_rejected: float = 0.75,
                 min_support: float = 0.5,
                 mode_radius: float = 2.0,
                 restart_std: tuple[float, float, float] = (0.3, 0.3, 0.1)) -> None:
        self.window = check_int(window, "window", low=2)
        self.nis_prob = check_real(nis_prob, "nis_prob", low=0.0, high=1.0, low_open=True,
                                   high_open=True)
        self.nis_cap = check_real(nis_cap, "nis_cap", low=0.0, low_open=True)
        self.disagree_distance = check_real(disagree_distance, "disagree_distance", low=0.0)
        self.disagree_heading = check_real(disagree_heading, "disagree_heading", low=0.0)
        self.disagree_fraction = check_real(disagree_fraction, "disagree_fraction", low=0.0,
                                            high=1.0, low_open=True)
        self.min_rejected = check_real(min_rejected, "min_rejected", low=0.0, high=1.0)
        self.min_support = check_real(min_support, "min_support", low=0.0, high=1.0,
                                      low_open=True)
        self.mode_radius = check_real(mode_radius, "mode_radius", low=0.0, low_open=True)
        std = np.asarray(restart_std, dtype=np.float64) if not isinstance(restart_std, str) \
            else np.zeros(0)
        if std.shape != (3,) or not np.all(np.isfinite(std)) or np.any(std <= 0):
            raise ValueError(f"restart_std must be 3 positive numbers, got {restart_std!r}")
        self.restart_std = std
        self.clear()

    def clear(self) -> None:
        """Forget the windows (after a reset or a restart)."""
        self._nis: deque[float] = deque(maxlen=self.window)
        self._disagree: deque[bool] = deque(maxlen=self.window)
        self._rejected: deque[bool] = deque(maxlen=self.window)
        self._proposals = np.zeros((0, 3))
        self._ages: list[int] = []

    def move_proposals(self, motion_model: Any, u: Array) -> None:
        """Move the stored proposals to the present: ``F(p, k U)`` (u already scaled by k)."""
        if len(self._proposals):
            self._proposals = predict_particles(motion_model, self._proposals, u)
            self._ages = [a + 1 for a in self._ages]
            keep = np.array(self._ages) < self.window
            self._proposals = self._proposals[keep]
            self._ages = [a for a, k in zip(self._ages, keep) if k]

    def observe(self, nis: float, dim_z: int, psi: Array, x: Array, P: Array,
                rejected: bool, forced: bool = False) -> Verdict:
        """Add one step: its NIS (NaN: none), psi*(w) (NaN: out of domain), the belief
        mean ``x`` (3,) and covariance ``P`` (3, 3), whether the measurement was rejected.
        ``forced``: the belief is known to be lost (an unknown start): restart as soon as
        the proposals agree."""
        self._rejected.append(bool(rejected))
        if np.isfinite(nis):
            self._nis.append(min(float(nis), self.nis_cap))
        if np.all(np.isfinite(psi)):
            self._disagree.append(self._disagrees(psi, x, P))
            self._proposals = np.vstack([self._proposals, psi[None]])
            self._ages.append(0)
        nis_high = self._nis_high(dim_z)
        disagree = (len(self._disagree) >= self.window // 2
                    and float(np.mean(self._disagree)) >= self.disagree_fraction)
        lost = forced or nis_high or disagree
        rejecting = float(np.mean(self._rejected)) >= self.min_rejected
        if (forced or (nis_high and disagree and rejecting)) \
                and len(self._proposals) >= self.window // 2:
            mode = find_modes(self._proposals, np.ones(len(self._proposals)),
                              self.mode_radius)[0]
            if mode.weight * len(self._proposals) >= self.min_support * self.window:
                return Verdict(lost, mode.mean, mode.cov + np.diag(self.restart_std ** 2))
        return Verdict(lost)

    def _disagrees(self, psi: Array, x: Array, P: Array) -> bool:
        sigma_xy = float(np.sqrt(max(np.linalg.eigvalsh(P[:2, :2])[-1], 0.0)))
        far = np.hypot(*(psi[:2] - x[:2])) > self.disagree_distance + 3.0 * sigma_xy
        turned = abs(float(wrap_angle(psi[2] - x[2]))) > \
            self.disagree_heading + 3.0 * float(np.sqrt(max(P[2, 2], 0.0)))
        return bool(far or turned)

    def _nis_high(self, dim_z: int) -> bool:
        n = len(self._nis)
        if n < self.window // 2:
            return False
        return float(np.mean(self._nis)) > chi2_band(dim_z, n, self.nis_prob)[1]
