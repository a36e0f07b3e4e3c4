"""How :class:`~localization.filtering.belief.BeliefFilter` recovers (a mixin): the restart
at psi* of one image after ``relocalize_after`` misses, every restart on trial against the
belief it replaced (:mod:`~localization.filtering.restart_trial`), and the divergence
monitor's restarts (docs/method.md §13, §13.1).

The host class provides ``ekf``, ``misses``, ``gated``, ``belief_status``, ``monitor``,
``localizer``, ``motion_model``, ``last_update``, ``_trial``, ``_refused``, ``_repeat_view``,
``_placed``, ``_forced``, ``_bumped``, ``_lost_now`` / ``_doubtful_now``, ``inflate_factor``,
``_start``, ``_from_image`` and ``_measurement``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from localization.filtering.ekf import OutOfDomainError, PoseEKF
from localization.filtering.restart_trial import RestartTrial, ViewOdometer
from localization.geometry import Array, wrap_angle

__all__ = ["RecoveryMixin"]

#: a step's control k U (2,) and its extra process noise (3, 3) or None (BeliefFilter._step_motion)
Motion = tuple[Array, Array | None]
MAX_HEADING_STD = 0.5  # rad: heading inflation stops there


class RecoveryMixin:
    """Restarts, their trials and the divergence watch of the belief filter."""

    ekf: PoseEKF | None
    misses: int
    gated: int
    belief_status: str
    monitor: Any
    localizer: Any
    motion_model: Any
    last_update: Any
    inflate_factor: float
    _trial: RestartTrial | None
    _refused: ViewOdometer | None
    _repeat_view: bool
    _placed: bool
    _forced: bool
    _bumped: int
    _lost_now: bool
    _doubtful_now: bool
    _start: Any
    _from_image: Any
    _measurement: Any

    def _relocalize(self, w: Array, status: str) -> str:
        """Restart at psi*(w) after ``relocalize_after`` misses, on trial against the belief it
        replaces (:meth:`_on_trial`): a belief coasting through views off the maps may be
        right, and one image's psi* may be a look-alike place. Nothing to come back to for a
        belief that was never placed (a start off the maps) or is itself still on trial."""
        prior, misses, keep = self.ekf, self.misses, self._placed and self._trial is None
        if self._refused is not None:
            return status  # the view of a refused restart: psi* would say the same again
        if not self._from_image(w):
            return status
        if keep:
            self._put_on_trial(prior, misses)
        return "relocalized"

    def _put_on_trial(self, replaced: PoseEKF | None, misses: int) -> None:
        """The restarted EKF is on trial against ``replaced`` (None: nothing to come back to),
        which had ``misses`` steps without an accepted measurement (:meth:`_on_trial`)."""
        self._trial = RestartTrial(replaced, misses)

    def _watch(self, motion: Motion, w: Array, nis: float, status: str) -> str:
        """Feed the divergence monitor (its proposals moved by this step's ``motion``);
        restart from the proposals when it says so."""
        assert self.ekf is not None and self.monitor is not None
        self.monitor.move_proposals(self.motion_model, motion[0])
        psi = np.asarray(self.localizer.measure(w, "pose"), dtype=np.float64)
        dim_z = self.last_update.dim_z if self.last_update is not None else 3
        verdict = self.monitor.observe(nis, dim_z, psi, self.ekf.x, self.ekf.P,
                                       status != "accepted", forced=self._forced)
        if verdict.restart is not None and self._restart_explains(
                verdict.restart, verdict.restart_cov, w):
            self.belief_status = "relocalizing"
            return "relocalized"
        self._lost_now, self._doubtful_now = verdict.lost, verdict.doubtful
        if verdict.drift is not None:
            self._widen_towards(verdict.drift)
        return status

    def _inflate_heading(self) -> None:
        """The heading variance times ``inflate_factor``, up to ``MAX_HEADING_STD`` squared
        (a gate that rejects the truth after a heading kick keeps rejecting it)."""
        assert self.ekf is not None
        P = self.ekf.P
        f = min(self.inflate_factor, MAX_HEADING_STD ** 2 / P[2, 2])
        if f > 1.0:
            d = np.array([1.0, 1.0, np.sqrt(f)])
            self.ekf.P = d[:, None] * P * d[None, :]
            if getattr(self.ekf, "P_xb", None) is not None:  # a congruence: Pa stays PSD
                self.ekf.P_xb = d[:, None] * self.ekf.P_xb

    def _widen_towards(self, pose: Array) -> None:
        """``P = P + d d^T``, ``d = pose - x`` (yaw wrapped): the images agree on a place a
        little off the belief (the monitor's drift test), which F and Q cannot explain (a
        shove); widened along ``d`` only, the next images may move the belief there (a
        belief 1.3 m off with position std 0.13 m crept back at 3 cm a step)."""
        assert self.ekf is not None
        d = np.asarray(pose, dtype=np.float64) - self.ekf.x
        d[2] = wrap_angle(d[2])
        self.ekf.P = self.ekf.P + np.outer(d, d)

    def _restart_explains(self, x0: Array, P0: Array, w: Array) -> bool:
        """Restart at ``x0``, ``P0`` and update with the current image, if that image's
        measurement passes the gate there (a cluster of aliased proposals whose place the
        image does not fit is refused; the belief is left alone)."""
        prior, kept, forced = self.ekf, (self.misses, self.gated), self._forced
        self._start(x0, P0)
        z, model, _ = self._measurement(self.ekf.x, w)
        try:
            ok = bool(np.all(np.isfinite(z))) and self.ekf.update(z, model).accepted
        except OutOfDomainError:
            ok = False
        if not ok and not forced:
            self.ekf, (self.misses, self.gated) = prior, kept
        elif ok and not forced and prior is not None:
            self._put_on_trial(prior, kept[0])
        return ok or forced  # an unknown start takes the agreed place either way

    def _on_trial(self, motion: Motion, w: Array, status: str) -> str:
        """One step of a (re)start on trial (:mod:`~localization.filtering.restart_trial`):
        the EKF it replaced runs on beside it; once the trial fails, that EKF comes back
        ("reverted"), or with nothing to come back to (a start from one image) the belief
        starts again at the current image's psi* ("relocalized"): on tuning city 13 a first
        image's psi* 11 m off stood for 78 steps until the 50-step restart."""
        trial = self._trial
        assert trial is not None and self.ekf is not None
        if trial.replaced is not None:
            replaced_ok = self._step_replaced(trial.replaced, motion, w)
            trial.misses = 0 if replaced_ok else trial.misses + 1
        self._repeat_view = not trial.record(status, *self._odometry(motion)) and (
            status == "accepted")
        if not (trial.confirmed or trial.failed):
            return status
        self._trial = None
        if trial.confirmed:
            return status
        if trial.replaced is None:
            return "relocalized" if self._from_image(w) else status
        self.ekf, self.misses, self.gated, self._bumped = trial.replaced, trial.misses, 0, 0
        self._refused = ViewOdometer() if trial.stalled else None
        self.belief_status = "tracking"
        if self.monitor is not None:
            self.monitor.clear()
        return "reverted"

    def _odometry(self, motion: Motion) -> tuple[float, float]:
        """The travel (m) and turn (rad) of one step's predicted ``motion`` (no update); none
        on a contact step predicted as blocked (``motion[1]``, its extra noise, not None):
        its turn is the commanded one with a standard deviation as large, so it shows no
        new view (held-out city 31, stop 41: a robot pinned on a building while its pilot
        commanded 0.05 rad per step confirmed a restart 22 m off from one view)."""
        if motion[1] is not None:
            return 0.0, 0.0
        d = np.asarray(self.motion_model.predict(np.zeros(3), motion[0]), dtype=np.float64)
        return float(np.hypot(d[0], d[1])), float(abs(wrap_angle(d[2])))

    def _track_refused(self, motion: Motion) -> None:
        """After a trial that failed on repeated views, count the odometry to the next new
        view; until then no restart (:meth:`_relocalize`) is tried from the same view."""
        if self._refused is not None:
            self._refused.add(*self._odometry(motion))
            if self._refused.new_view:
                self._refused = None

    def _step_replaced(self, old: PoseEKF, motion: Motion, w: Array) -> bool:
        """Predict with this step's ``motion`` and update the EKF a restart replaced; whether
        it accepted the image."""
        old.predict(*motion)
        z, model, _ = self._measurement(old.x, w)
        try:
            return bool(np.all(np.isfinite(z))) and old.update(z, model).accepted
        except OutOfDomainError:
            return False
