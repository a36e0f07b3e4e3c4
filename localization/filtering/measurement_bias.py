"""A measurement bias that persists from frame to frame: the EKF carries it as an AR(1) state.

The GSE maps err in runs, not frame by frame: psi* is biased along a street for several
steps, and an EKF that takes each frame as independent follows the bias and ends
over-confident (docs/benchmarks.md §8, stop 68: on tuning city 13 under overcast the belief
sat 0.17 m behind the robot with a 0.056 m standard deviation, NEES 24.6, while its whitened
innovations had variances 0.19-0.72). The whitened residuals are autocorrelated on every
drive (lag 1: 0.3-0.7). The standard remedy is to augment the state with the coloured part
of the noise (Bar-Shalom, Li and Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, §8.2; Gelb, "Applied Optimal Estimation", 1974, §4.5)::

    z_k = h(x_k) + b_k + v_k,          v_k ~ N(0, R - rho R0)            (white part)
    b_k = phi b_{k-1} + n_k,           n_k ~ N(0, (1 - phi^2) rho R0)   (stationary Cov(b) = rho R0)

so the total noise keeps the calibrated ``R``, a share ``rho`` of it correlated with
per-step correlation ``phi``. ``R0`` is the model's noise of the place (its ``gate_R(x)``
when it has one, else R): the bias belongs to the map, so a frame's own inflation (an
unfamiliar image, :mod:`~localization.filtering.heteroscedastic_noise`) or the innovations'
scaling (:mod:`~localization.filtering.adaptive_noise`) widens the white part only; with
one global R, ``R0 = R`` and the white part is ``(1 - rho) R``. With ``P_xb`` the pose-bias cross-covariance and ``P_bb`` the
bias covariance, one step of :class:`BiasedPoseEKF` is, in the code's names::

    predict:  x = F(x, u),  P = F P F^T + Q,  b = phi b,  P_xb = phi F P_xb,
              P_bb = phi^2 P_bb + (1 - phi^2) rho R0
    update:   Ha = [H, I],  Pa = [[P, P_xb], [P_xb^T, P_bb]],  y = residual(z, h(x) + b),
              NIS = y^T (Ha Pa Ha^T + (1 - rho) R0)^-1 y  (gated as PoseEKF, on R0),
              S = Ha Pa Ha^T + R - rho R0,  K = Pa Ha^T S^-1,  [x; b] += K y,
              Pa = (I - K Ha) Pa (I - K Ha)^T + K (R - rho R0) K^T

The pose part ``x``, ``P`` is what the belief reports; the bias starts at zero with its
stationary covariance at the first update after each (re)start. ``rho = 0.45``, ``phi =
0.65`` are the middle of the fits on tuning cities 11, 13 and 14 (rho 0.40-0.47, phi
0.62-0.68 from the whitened residuals' autocorrelation at lags 1-5).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from localization._validation import check_real, check_settings
from localization.filtering.ekf import (
    MeasurementModel,
    PoseEKF,
    QFunction,
    UpdateResult,
    gate_threshold,
)
from localization.geometry import Array, MotionModel, wrap_angle

__all__ = ["BiasedPoseEKF", "MeasurementBias", "make_ekf", "measurement_bias_for"]


@dataclass(frozen=True)
class MeasurementBias:
    """Settings of the AR(1) measurement bias (see the module docstring).

    Parameters
    ----------
    rho : float in [0, 1)
        Share of R that is the persistent bias (0: the plain EKF).
    phi : float in [0, 1)
        Per-step correlation of the bias.
    """

    rho: float = 0.45
    phi: float = 0.65

    def __post_init__(self) -> None:
        check_real(self.rho, "rho", low=0.0, high=1.0, high_open=True)
        check_real(self.phi, "phi", low=0.0, high=1.0, high_open=True)


def measurement_bias_for(option: bool | dict[str, Any] | MeasurementBias) -> MeasurementBias | None:
    """The :class:`MeasurementBias` a ``measurement_bias`` option asks for (None: off;
    :func:`~localization._validation.check_settings`)."""
    return check_settings(option, "measurement_bias", MeasurementBias)


class BiasedPoseEKF(PoseEKF):
    """:class:`~localization.filtering.ekf.PoseEKF` whose measurements carry an AR(1) bias.

    Parameters are PoseEKF's, and ``bias`` (:class:`MeasurementBias`).

    Attributes
    ----------
    b : ndarray (dim_z,) or None
        The bias estimate (None before the first update).
    P_bb : ndarray (dim_z, dim_z) or None
        Its covariance.
    P_xb : ndarray (3, dim_z) or None
        The pose-bias cross-covariance.
    """

    def __init__(self, motion_model: MotionModel, Q: ArrayLike | QFunction, x0: ArrayLike,
                 P0: ArrayLike, gate_probability: float | None = 0.997,
                 bias: MeasurementBias | None = None) -> None:
        super().__init__(motion_model, Q, x0, P0, gate_probability=gate_probability)
        self.bias = bias or MeasurementBias()
        self.b: Array | None = None
        self.P_bb: Array | None = None
        self.P_xb: Array | None = None
        self._R_b: Array | None = None  # the stationary Cov(b) = rho R0 of the last update

    def predict(self, u: ArrayLike, Q_extra: ArrayLike | None = None) -> None:
        """PoseEKF's prior, and ``b = phi b``, ``P_xb = phi F P_xb``,
        ``P_bb = phi^2 P_bb + (1 - phi^2) rho R0``."""
        super().predict(u, Q_extra)
        if self.b is None:
            return
        phi = self.bias.phi
        assert self.P_bb is not None and self.P_xb is not None and self._R_b is not None
        self.b = phi * self.b
        self.P_xb = phi * (self.F @ self.P_xb)
        self.P_bb = phi ** 2 * self.P_bb + (1.0 - phi ** 2) * self._R_b

    def _joint(self, dim_z: int, R: Array) -> tuple[Array, Array]:
        """The bias ``b`` and the joint covariance ``Pa`` (3 + dim_z square). A bias of
        another width (a new model) starts from its stationary state; a joint covariance
        made indefinite by a caller shrinking P drops ``P_xb`` (the belief's own changes of
        P keep it positive semi-definite: the heading inflation scales ``P_xb`` with P, the
        divergence monitor's widening only adds to P)."""
        rho = self.bias.rho
        if self.b is None or self.b.shape != (dim_z,):
            self.b, self.P_bb, self.P_xb = np.zeros(dim_z), rho * R, np.zeros((3, dim_z))
        assert self.P_bb is not None and self.P_xb is not None
        Pa = np.block([[self.P, self.P_xb], [self.P_xb.T, self.P_bb]])
        try:
            np.linalg.cholesky(Pa + 1e-12 * np.eye(len(Pa)))
        except np.linalg.LinAlgError:
            self.P_xb = np.zeros((3, dim_z))
            Pa = np.block([[self.P, self.P_xb], [self.P_xb.T, self.P_bb]])
        return self.b, Pa

    def update(self, z: ArrayLike, model: MeasurementModel) -> UpdateResult:  # type: ignore[override]
        """Gated update of the pose and the bias (the module docstring's equations)."""
        z, z_pred, H, R, _ = self.innovation(z, model)
        dim_z, rho = z.shape[0], self.bias.rho
        R0 = self.gate_noise(model, R)
        b, Pa = self._joint(dim_z, R0)
        self._R_b = rho * R0  # the map's bias: without the frame's inflation or scaling
        Ha = np.hstack([H, np.eye(dim_z)])
        y = np.asarray(model.residual(z, z_pred + b), dtype=np.float64)
        HPH = Ha @ Pa @ Ha.T
        white = R - rho * R0  # the rest of R (>= (1 - rho) R0: inflation only grows R)
        try:
            nis = float(y @ cho_solve(cho_factor(HPH + (1.0 - rho) * R0), y))
            S = cho_factor(HPH + white)
        except LinAlgError:
            raise ValueError("innovation covariance S = Ha Pa Ha^T + R - rho R0 is not "
                             "positive definite") from None
        threshold = gate_threshold(self.gate_probability, dim_z)
        if nis > threshold:
            return UpdateResult(nis=nis, accepted=False, dim_z=dim_z, threshold=threshold)
        K = cho_solve(S, Ha @ Pa).T
        d = K @ y
        A = np.eye(len(Pa)) - K @ Ha
        Pa = A @ Pa @ A.T + K @ white @ K.T
        Pa = 0.5 * (Pa + Pa.T)
        self.x = self.x + d[:3]
        self.x[2] = wrap_angle(self.x[2])
        self.b = b + d[3:]
        self.P, self.P_xb, self.P_bb = Pa[:3, :3], Pa[:3, 3:], Pa[3:, 3:]
        self.y, self.z = y, z
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        return UpdateResult(nis=nis, accepted=True, dim_z=dim_z, threshold=threshold)

    def snapshot(self) -> tuple[Any, ...]:
        """PoseEKF's snapshot and the bias state."""
        return super().snapshot() + tuple(
            None if a is None else a.copy() for a in (self.b, self.P_bb, self.P_xb, self._R_b))

    def restore(self, state: tuple[Any, ...]) -> None:
        """Back to a :meth:`snapshot`."""
        super().restore(state[:2])
        self.b, self.P_bb, self.P_xb, self._R_b = state[2:]


def make_ekf(motion_model: MotionModel, Q: ArrayLike | QFunction, x0: ArrayLike, P0: ArrayLike,
             gate_probability: float | None, bias: MeasurementBias | None) -> PoseEKF:
    """A :class:`BiasedPoseEKF` with ``bias``, or a plain PoseEKF when ``bias`` is None."""
    if bias is None:
        return PoseEKF(motion_model, Q, x0, P0, gate_probability=gate_probability)
    return BiasedPoseEKF(motion_model, Q, x0, P0, gate_probability=gate_probability, bias=bias)
