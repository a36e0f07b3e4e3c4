"""ModeTracker: an EKF on the particle belief's dominant hypothesis.

A particle cloud is the right tool to find the pose (a kidnap, a global start, two look-alike
places) but a poor one to report it while tracking: the Augmented-MCL injections that make
recovery fast also drop particles on the places an aliased image suggests, and a run of
aliased frames now and then pulls the heaviest mode over for a few steps. The EKF
(:class:`~localization.filtering.belief.BeliefFilter`, no restart of its own; of the
divergence monitor at most its drift test, ``drift``) tracks to a few centimetres with a
consistent covariance but cannot tell it is lost.
The tracker runs both on the same images and controls and lets the particles say which
hypothesis the EKF follows. With the names of the code, after each particle step::

    support   = sum_i w_i [ d(X_i, x) < radius ],  d^2 = dx^2 + dy^2 + (heading_scale dyaw)^2
    condemned = NIS > strong_nis on the last strong_steps steps, gated max_gated steps,
                or support < support_weight max_unsupported steps (all in a row);
                after a restart until supported for probation steps in a row,
                and after a contact that contradicted the particles until they support it
    support >= support_weight or not condemned  -> report the EKF's x, P        ("ekf")
    condemned, mode weight >= confident_weight  -> restart the EKF at the dominant
                                                   mode (mean, cov), report it  ("restarted")
    condemned otherwise                         -> report the dominant mode     ("mode")

(x, P the EKF's mean and covariance, NIS its normalised innovation squared, w_i and X_i the
particles' weights and poses.) Aliased images come in runs, and over a few steps a run
looks like a kidnap: the images agree with another place along a path the motion allows.
On the tuning cities 11-13 (24 nominal drives of 300 steps, 48 kidnaps of 5-17 m) a run of
19 frames whose psi* sat 1.2-4.9 m off drew the particles' heaviest mode 1.5-6 m away while
the EKF gated them all and stayed within 0.15 m on dead reckoning; another, 3.5-6.7 m off,
kept the NIS above 100 on 13 frames of 14. After a kidnap the NIS exceeds 100 from the
first or second step on. ``strong_steps`` trades the two: 3 steps gave kidnap recovery
median 4 / p95 12 steps but a pooled nominal RMSE of 0.31 m; 5: 4 / 22, 0.25 m; 8 (the
default): 7 / 24 (98 % within 30 steps), 0.127 m (the EKF: 0.088 m). The particles left
the EKF's pose for at most 11 steps in a row on the first 6 nominal drives
(``max_unsupported`` 20). A start from the image or a global start (no known pose) starts
condemned: the report follows the particles until they agree.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization._validation import check_int, check_real
from localization.filtering._modes import Mode
from localization.filtering.belief import BeliefFilter
from localization.filtering.divergence import DRIFT_DISTANCE
from localization.filtering.map_contact import Contact, FreeSpace
from localization.geometry import Array, wrap_angle

__all__ = ["TRACKER_SOURCES", "ModeTracker", "make_tracker"]

#: what the report came from at the last step (see the module docstring)
TRACKER_SOURCES = ("ekf", "restarted", "mode")


class ModeTracker:
    """EKF on the dominant hypothesis of a particle belief (see the module docstring).

    Parameters
    ----------
    localizer : AppearanceLocalizer
        Fitted, with its noise model.
    motion_model : object
        F (the env's ``motion_model``).
    measurement : {"representation", "pose", "features"}
        The EKF's measurement model.
    support_weight : float in (0, 1]
        The EKF is followed while at least this weight of particles lies within ``radius``.
    radius, heading_scale : float
        The support kernel (m) and metres per radian.
    confident_weight : float in (0, 1]
        Weight of the dominant mode needed to restart the EKF there.
    strong_nis : float
        NIS that counts as a strong contradiction (default 100, about 7 times the 99.7 %
        gate of 3 degrees of freedom; chosen on the tuning cities 11-13).
    strong_steps : int
        Strong contradictions in a row that condemn the EKF (8: see the module docstring).
    max_gated : int
        Gated steps in a row that condemn the EKF (a kidnap too small for strong NIS).
    max_unsupported : int
        Steps in a row with support below ``support_weight`` that condemn the EKF (it
        drifted, or the images were out of the training domain).
    probation : int
        A restarted EKF stays condemned (restarted again as soon as the particles leave
        it) until it has had their support for this many steps in a row: a restart from a
        broad mode can settle on the wrong place along a street that looks alike.
    alpha : array_like (3,), optional
        The EKF's body-frame inflation; default the localizer's calibrated consistency.
    drift : bool
        Give the EKF the divergence monitor's drift test alone
        (``DivergenceMonitor(drift_only=True, drift_distance=DRIFT_DISTANCE)``, with its
        default jump condition ``drift_change``): psi* suddenly agreeing a little off it
        widens P towards them (a shove), with no restart or "lost" of its own. Off by
        default, as the EKF's (``localization.filtering.divergence``: it pulled right
        beliefs onto biased psi* on the global benchmark, held out at stop 54 too).
        Not with a localizer of several districts (whose EKF takes no monitor).
    offset_doubt : float or None
        Give the EKF the divergence monitor's offset test (``DivergenceMonitor(offset_doubt=
        ...)``, status only): :attr:`images_doubt` while the recent psi* put the robot this
        many metres (beyond 3 sigma) off the EKF; None (the default): off. Not with a
        localizer of several districts.
    free_space : callable, optional
        The map (``city.free_mask``), given to the EKF with its contact projection
        (:class:`~localization.filtering.belief.BeliefFilter`'s ``free_space`` and
        ``project_contacts``): a contact with the city touched where the EKF's belief
        has room moves its mean to the nearest pose that explains it, as the EKF alone
        does. Without it a tracker EKF pushed 1 m sideways kept being reported, and
        the robot kept bumping the wall, while the particles' mode already sat at it
        (their contact spread never ran: the particles were not contradicted).
    contact_motion : {"blocked", "commanded"}
        How the EKF predicts a contact step (the particles' setting).

    Attributes
    ----------
    ekf : BeliefFilter
    source : one of ``TRACKER_SOURCES`` (after :meth:`step`; "ekf" after :meth:`reset`)
    support : float
        The support of the EKF's mean at the last step.
    restarts : int
        EKF restarts since :meth:`reset`.
    """

    def __init__(self, localizer: Any, motion_model: Any, measurement: str = "representation",
                 support_weight: float = 0.05, radius: float = 1.0, heading_scale: float = 2.0,
                 confident_weight: float = 0.8, strong_nis: float = 100.0,
                 strong_steps: int = 8, max_gated: int = 30, max_unsupported: int = 20,
                 probation: int = 20,
                 alpha: ArrayLike | None = None, drift: bool = False,
                 free_space: FreeSpace | None = None, contact_motion: str = "blocked",
                 offset_doubt: float | None = None) -> None:
        for name, v in (("support_weight", support_weight),
                        ("confident_weight", confident_weight)):
            check_real(v, name, low=0.0, high=1.0, low_open=True)
        for name, v in (("radius", radius), ("heading_scale", heading_scale),
                        ("strong_nis", strong_nis)):
            check_real(v, name, low=0.0, low_open=True)
        self.strong_steps = check_int(strong_steps, "strong_steps", low=1)
        self.max_gated = check_int(max_gated, "max_gated", low=1)
        self.max_unsupported = check_int(max_unsupported, "max_unsupported", low=1)
        self.probation = check_int(probation, "probation", low=1)
        self.strong_nis = float(strong_nis)
        if not isinstance(drift, (bool, np.bool_)):
            raise TypeError(f"drift must be a bool, got {drift!r}")
        one_map = not callable(getattr(localizer, "local", None))
        tests = {"drift_distance": DRIFT_DISTANCE if drift else None,
                 "offset_doubt": offset_doubt}
        monitor = one_map and any(v is not None for v in tests.values())
        self.ekf = BeliefFilter(localizer, motion_model, measurement, relocalize_after=None,
                                alpha=alpha, detect_divergence={"drift_only": True, **tests}
                                if monitor else False, free_space=free_space,
                                contact_motion=contact_motion)
        self.support_weight, self.confident_weight = float(support_weight), float(confident_weight)
        self.radius, self.heading_scale = float(radius), float(heading_scale)
        self.source, self.support, self.restarts = "ekf", 1.0, 0
        self.strong = self.unsupported = self.supported = 0
        self.condemned = False
        self._mode: Mode | None = None

    @property
    def mean(self) -> Array:
        """The reported pose (3,): the EKF's, or the dominant mode's when it reports it."""
        return self._mode.mean.copy() if self._mode is not None else self.ekf.x

    @property
    def images_doubt(self) -> bool:
        """The EKF's monitor doubted the last step's images (its drift or offset test)."""
        return self.ekf.images_doubt

    @property
    def cov(self) -> Array:
        """The reported covariance (3, 3)."""
        return self._mode.cov.copy() if self._mode is not None else self.ekf.P

    def reset(self, w: ArrayLike, mode: Mode, known: bool) -> None:
        """Start the EKF at ``mode`` (the particles' dominant mode after their reset);
        ``known``: the start pose was given (else the EKF starts on probation)."""
        self._restart(w, mode)
        self.restarts, self.condemned = 0, not known
        self.source, self._mode = ("ekf", None) if known else ("mode", mode)

    def _restart(self, w: ArrayLike, mode: Mode) -> None:
        self.ekf.reset(w, mode.mean, mode.cov)
        self.support, self.strong, self.unsupported, self.supported = 1.0, 0, 0, 0
        self.condemned = True  # on probation until supported for `probation` steps
    def contradict(self) -> None:
        """A contact contradicted the particles (:mod:`~.contact_spread`): the EKF, on their
        old hypothesis, is condemned until they support it again."""
        self.condemned, self.supported = True, 0

    def support_of(self, particles: Array, weights: Array) -> float:
        """Weight (float) of the particles (N, 3) within ``radius`` of the EKF's mean."""
        d = particles - self.ekf.x
        d2 = d[:, 0] ** 2 + d[:, 1] ** 2 + (self.heading_scale * wrap_angle(d[:, 2])) ** 2
        return float(weights[d2 < self.radius ** 2].sum())

    def step(self, u: ArrayLike, w: ArrayLike, particles: Array, weights: Array,
             dominant: Mode, contact: Contact = False, bearing: float | None = None) -> str:
        """Step the EKF with the control ``u`` (2,) and features ``w`` (m,) (``contact``: what
        a contact step touched, ``bearing``: where, rad from the heading), then choose the
        report from the particles (N, 3), their weights (N,) and dominant mode.

        Returns
        -------
        source : one of ``TRACKER_SOURCES``
        """
        nis, _ = self.ekf.step(u, w, contact, bearing)
        if np.isfinite(nis):  # out of domain (NaN) neither adds nor breaks a run
            self.strong = self.strong + 1 if nis > self.strong_nis else 0
        self._mode = None
        self.support = self.support_of(particles, weights)
        ok = self.support >= self.support_weight
        self.unsupported, self.supported = (0, self.supported + 1) if ok else \
            (self.unsupported + 1, 0)
        self.condemned &= self.supported < self.probation
        self.condemned |= (self.strong >= self.strong_steps or self.ekf.gated >= self.max_gated
                           or self.unsupported >= self.max_unsupported)
        if ok or not self.condemned:
            self.source = "ekf"
        elif dominant.weight >= self.confident_weight:
            self._restart(w, dominant)
            self.source, self.restarts = "restarted", self.restarts + 1
        else:
            self._mode, self.source = dominant, "mode"
        return self.source


def make_tracker(track_mode: bool | dict[str, Any], localizer: Any, motion_model: Any,
                 measurement: str, **defaults: Any) -> ModeTracker | None:
    """The tracker a particle belief's ``track_mode`` asks for: None (False), one with the
    ``defaults`` (True), or one with a dict of settings over the ``defaults``."""
    if isinstance(track_mode, dict):
        return ModeTracker(localizer, motion_model, measurement, **{**defaults, **track_mode})
    if not isinstance(track_mode, bool):
        raise TypeError(f"track_mode must be a bool or a dict of ModeTracker settings, got "
                        f"{track_mode!r}")
    return ModeTracker(localizer, motion_model, measurement, **defaults) if track_mode else None
