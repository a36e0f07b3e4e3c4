"""Pose EKF (seed §III.D / IV): known motion model F as prediction, GSE maps as measurements.

Built on :class:`filterpy.kalman.ExtendedKalmanFilter`, whose ``predict`` (``P = F P F^T + Q``)
and ``update`` (gain and Joseph-form covariance) are reused unchanged. This module adds

the unicycle prediction ``x = F(x, u)`` with ``F = F_x`` at the prior state and a fixed or
``Q(x, u)`` process noise; measurement models as objects (``h``, ``H``, ``R``, ``residual``);
chi-square gating on the NIS; heading wrapping in state and residuals; NEES and chi-square bands.
State ``x = [x, y, yaw]`` (metres, radians, yaw in (-pi, pi]), control ``u = [v, w]``.

Equations, with the names used in the code::

    predict:  F = dF/dx (x, u),  x = F(x, u),  P = F P F^T + Q
    update:   H = dh/dx (x),  y = residual(z, h(x)),  S = H P H^T + R,  NIS = y^T S^-1 y
              reject if NIS > chi2.ppf(gate_probability, dim_z)   (x, P unchanged)
              K = P H^T S^-1,  x = x + K y,  P = (I - K H) P (I - K H)^T + K R K^T
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from numpy.typing import ArrayLike
from scipy.linalg import LinAlgError, cho_factor, cho_solve
from scipy.stats import chi2

from localization._validation import check_array, check_real
from localization.geometry import Array, MotionModel, pose_residual, wrap_angle

QFunction = Callable[[Array, Array], Array]
_SYM_TOL = 1e-9


class MeasurementModel(Protocol):
    """A measurement model: ``z = h(x) + v``, ``v ~ N(0, R)``.

    ``h(x) -> (dim_z,)``, ``H(x) -> (dim_z, 3)`` (= dh/dx), ``R`` (dim_z, dim_z) and
    ``residual(z, z_pred) -> (dim_z,)``. A model may also define ``R_at(x)`` for a state
    dependent noise; the filter calls it when present and reads ``R`` otherwise; and
    ``gate_R(x)``: the noise the NIS gate uses instead of R (a model that inflates R for an
    unfamiliar image gates it as a familiar one: the inflation lowers its weight, it never
    lets through a measurement the gate would reject).
    """

    R: ArrayLike
    def h(self, x: Array) -> Array: ...
    def H(self, x: Array) -> Array: ...
    def residual(self, z: Array, z_pred: Array) -> Array: ...


class OutOfDomainError(ValueError):
    """The measurement model cannot predict at the state: ``h(x)`` or ``H(x)`` is NaN
    (e.g. a learned map queried away from its training data). No update is possible."""


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one :meth:`PoseEKF.update`.

    Attributes
    ----------
    nis : float
        Normalized innovation squared ``y^T S^-1 y`` (computed before the update).
    accepted : bool
        False when the gate rejected the measurement (state and covariance unchanged).
    dim_z : int
        Measurement dimension (the chi-square degrees of freedom of ``nis``).
    threshold : float
        Gate ``chi2.ppf(gate_probability, dim_z)``; ``inf`` when gating is disabled.
    """

    nis: float
    accepted: bool
    dim_z: int
    threshold: float


@lru_cache(maxsize=64)
def gate_threshold(gate_probability: float | None, dim_z: int) -> float:
    """``chi2.ppf(gate_probability, dim_z)`` (cached), ``inf`` when gating is disabled."""
    return np.inf if gate_probability is None else float(chi2.ppf(gate_probability, dim_z))


def _finite_vector(v: ArrayLike, name: str, dim: int | None = None) -> Array:
    return check_array(v, name, shape=(dim,))


def check_gate_probability(gate_probability: object) -> float | None:
    """The NIS gate's chi-square probability: a number in (0, 1), or None (no gate)."""
    if gate_probability is None:
        return None
    return check_real(gate_probability, "gate_probability", low=0.0, high=1.0, low_open=True,
                      high_open=True)


def check_motion_model(motion_model: object) -> MotionModel:
    """``motion_model`` if it has F's ``predict`` and ``jacobian_pose`` (TypeError otherwise)."""
    if not all(callable(getattr(motion_model, m, None)) for m in ("predict", "jacobian_pose")):
        raise TypeError("motion_model must have predict(pose, u) and jacobian_pose(pose, u) "
                        f"(e.g. envs.motion_model.UnicycleModel), got {type(motion_model).__name__}")
    return motion_model  # type: ignore[return-value]


def _covariance(C: ArrayLike, name: str, dim: int, definite: bool = True) -> Array:
    """Return C as float64 after checking shape (dim, dim), finiteness, symmetry and definiteness."""
    C = check_array(C, name, shape=(dim, dim))
    scale = max(1.0, float(np.max(np.abs(C))))
    if not np.allclose(C, C.T, rtol=0.0, atol=_SYM_TOL * scale):
        raise ValueError(f"{name} must be symmetric (max |C - C^T| = {np.max(np.abs(C - C.T)):.3g})")
    if definite:
        try:
            np.linalg.cholesky(C)
        except np.linalg.LinAlgError:
            raise ValueError(f"{name} must be positive definite") from None
    elif np.linalg.eigvalsh(C)[0] < -_SYM_TOL * scale:
        raise ValueError(f"{name} must be positive semi-definite")
    return 0.5 * (C + C.T)


def noise_at(model: MeasurementModel, x: Array) -> Array:
    """A measurement model's R at ``x``: its ``R_at(x)`` when it has one, else its ``R``."""
    R_at = getattr(model, "R_at", None)
    return np.asarray(R_at(x) if callable(R_at) else model.R, dtype=np.float64)


class FunctionMeasurement:
    """Measurement model from callables: ``z = h(x) + v``, ``v ~ N(0, R)``.

    Used by the localizer for the GSE maps, e.g. "features" (``z = w``, ``h = Phi*``,
    ``H = dPhi*/dtheta``) and "representation" (``z = r*(w)``, ``h = R*(theta)``,
    ``H = dR*/dtheta``).

    Parameters
    ----------
    h : callable
        ``h(x) -> z_pred`` with x (3,) and z_pred (dim_z,).
    H : callable
        ``H(x) -> (dim_z, 3)``, the Jacobian dh/dx at x.
    R : array_like (dim_z, dim_z) or callable
        Measurement noise covariance (symmetric positive definite), or ``R(x) -> (dim_z, dim_z)``.
    residual : callable, optional
        ``residual(z, z_pred) -> y`` (dim_z,); default ``z - z_pred``.
    """

    def __init__(
        self,
        h: Callable[[Array], ArrayLike],
        H: Callable[[Array], ArrayLike],
        R: ArrayLike | Callable[[Array], ArrayLike],
        residual: Callable[[Array, Array], ArrayLike] | None = None,
    ) -> None:
        if not (callable(h) and callable(H)):
            raise TypeError("h and H must be callables h(x) -> (dim_z,), H(x) -> (dim_z, 3)")
        self._h, self._H = h, H
        if callable(R):
            self.R = R
        else:
            R = check_array(R, "R", ndim=2, what="(dim_z, dim_z)")
            self.R = _covariance(R, "R", R.shape[0])
        self._residual = residual

    def h(self, x: Array) -> Array:
        """Predicted measurement ``h(x)``, shape (dim_z,)."""
        return np.asarray(self._h(x), dtype=np.float64)

    def H(self, x: Array) -> Array:
        """Jacobian ``dh/dx`` at x, shape (dim_z, 3)."""
        return np.asarray(self._H(x), dtype=np.float64)

    def R_at(self, x: Array) -> Array:
        """Noise covariance at x, shape (dim_z, dim_z)."""
        return np.asarray(self.R(x) if callable(self.R) else self.R, dtype=np.float64)

    def residual(self, z: Array, z_pred: Array) -> Array:
        """Innovation ``y = z - z_pred`` (or the user's residual), shape (dim_z,)."""
        if self._residual is None:
            return np.subtract(z, z_pred)
        return np.asarray(self._residual(z, z_pred), dtype=np.float64)


class PoseMeasurement(FunctionMeasurement):
    """Direct pose measurement (e.g. ``z = psi*(w)``): ``h(x) = x``, ``H = I_3``, yaw residual wrapped.

    Parameters
    ----------
    R : array_like (3, 3)
        Measurement noise covariance, symmetric positive definite.
    """

    def __init__(self, R: ArrayLike) -> None:
        super().__init__(lambda x: np.array(x, dtype=np.float64), lambda x: np.eye(3), R,
                         residual=pose_residual)
        if self.R.shape != (3, 3):
            raise ValueError(f"PoseMeasurement R must have shape (3, 3), got {self.R.shape}")


def control_noise_Q(motion_model: MotionModel, M: ArrayLike, Q0: ArrayLike | None = None
                    ) -> QFunction:
    """Process noise from control noise: ``Q(x, u) = F_u M F_u^T + Q0``.

    Parameters
    ----------
    motion_model : MotionModel
        Provides ``jacobian_control(x, u) -> F_u`` (3, 2).
    M : array_like (2, 2)
        Covariance of the control noise on ``u = [v, w]``.
    Q0 : array_like (3, 3), optional
        Additive pose noise (default zero), e.g. for slip not explained by the controls.

    Returns
    -------
    callable
        ``Q(x, u) -> (3, 3)``, usable as ``PoseEKF(Q=...)``.
    """
    M = _covariance(M, "M", 2, definite=False)
    Q0 = np.zeros((3, 3)) if Q0 is None else _covariance(Q0, "Q0", 3, definite=False)

    def Q(x: Array, u: Array) -> Array:
        F_u = motion_model.jacobian_control(x, u)
        return F_u @ M @ F_u.T + Q0

    return Q


class PoseEKF(ExtendedKalmanFilter):
    """Extended Kalman filter on the pose ``x = [x, y, yaw]`` with a known motion model.

    Attributes follow filterpy: ``x`` (3,), ``P`` (3, 3), ``F``, ``Q`` (last used), and after an
    accepted update ``y``, ``S``, ``K``, ``z``; ``x_prior``/``P_prior``, ``x_post``/``P_post``.

    Parameters
    ----------
    motion_model : MotionModel
        ``predict(x, u) -> (3,)`` and ``jacobian_pose(x, u) -> F`` (3, 3), e.g. ``UnicycleModel``.
    Q : array_like (3, 3) or callable
        Process noise: a fixed symmetric positive semi-definite matrix, or ``Q(x, u) -> (3, 3)``
        evaluated at the prior state and control of each step (see :func:`control_noise_Q`
        for ``F_u M F_u^T + Q0``).
    x0 : array_like (3,)
        Initial pose estimate (yaw is wrapped).
    P0 : array_like (3, 3)
        Initial covariance, symmetric positive definite.
    gate_probability : float or None
        Measurements with ``NIS > chi2.ppf(gate_probability, dim_z)`` are rejected; None disables
        gating. Default 0.997 (a correct measurement is rejected 0.3 % of the time).
    """

    def __init__(
        self,
        motion_model: MotionModel,
        Q: ArrayLike | QFunction,
        x0: ArrayLike,
        P0: ArrayLike,
        gate_probability: float | None = 0.997,
    ) -> None:
        super().__init__(dim_x=3, dim_z=3, dim_u=2)
        gate_probability = check_gate_probability(gate_probability)
        self.motion_model = check_motion_model(motion_model)
        self.gate_probability = gate_probability
        self._Q_fun: QFunction | None = Q if callable(Q) else None
        if self._Q_fun is None:
            self.Q = _covariance(Q, "Q", 3, definite=False)
        x0 = _finite_vector(x0, "x0", 3)
        self.x = np.array([x0[0], x0[1], wrap_angle(x0[2])])
        self.P = _covariance(P0, "P0", 3)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()

    def predict_x(self, u: ArrayLike = 0) -> None:
        """State prediction ``x = F(x, u)`` through the motion model (called by filterpy)."""
        self.x = self.motion_model.predict(self.x, u)

    def predict(self, u: ArrayLike, Q_extra: ArrayLike | None = None  # type: ignore[override]
                ) -> None:
        """Prior: ``F = dF/dx (x, u)``, ``x = F(x, u)``, ``P = F P F^T + Q (+ Q_extra)``.

        Parameters
        ----------
        u : array_like (2,)
            Control ``[v, w]`` held over one step.
        Q_extra : array_like (3, 3), optional
            More process noise for this step only (e.g. a contact's, ``map_contact.blocked_motion``).
        """
        u = _finite_vector(u, "u", 2)
        self.F = self.motion_model.jacobian_pose(self.x, u)
        if self._Q_fun is not None:
            self.Q = _covariance(self._Q_fun(self.x, u), "Q(x, u)", 3, definite=False)
        super().predict(u)
        self.x[2] = wrap_angle(self.x[2])
        if Q_extra is not None:
            self.P = self.P + _covariance(Q_extra, "Q_extra", 3, definite=False)
        self.P = 0.5 * (self.P + self.P.T)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def innovation(self, z: ArrayLike, model: MeasurementModel
                   ) -> tuple[Array, Array, Array, Array, Array]:
        """Validated ``z``, ``z_pred = h(x)``, ``H``, ``R`` and ``y = residual(z, z_pred)``.

        Raises
        ------
        OutOfDomainError
            If ``h(x)`` or ``H(x)`` is NaN (the model has no prediction at x).
        ValueError
            If z is not finite, or shapes of z, h(x), H(x), R disagree, or R is not symmetric
            positive definite.
        """
        if not all(callable(getattr(model, m, None)) for m in ("h", "H", "residual")):
            raise TypeError("model must be a measurement model with h(x), H(x), R and "
                            f"residual(z, z_pred), got {type(model).__name__}")
        z_pred = np.asarray(model.h(self.x), dtype=np.float64)
        if z_pred.ndim != 1:
            raise ValueError(f"h(x) must have shape (dim_z,), got {z_pred.shape}")
        if np.isnan(z_pred).any():
            raise OutOfDomainError(f"the measurement model has no prediction at x = {self.x}")
        z_pred = _finite_vector(z_pred, "h(x)")
        dim_z = z_pred.shape[0]
        z = check_array(z, "z", ndim=1)
        if z.shape != (dim_z,):
            raise ValueError(f"z has shape {z.shape} but the model predicts shape {(dim_z,)}")
        H = np.asarray(model.H(self.x), dtype=np.float64)
        if H.shape != (dim_z, 3):
            raise ValueError(f"H(x) must have shape {(dim_z, 3)}, got {H.shape}")
        if np.isnan(H).any():
            raise OutOfDomainError(f"the measurement model has no Jacobian at x = {self.x}")
        if not np.all(np.isfinite(H)):
            raise ValueError("H(x) contains inf")
        R = _covariance(noise_at(model, self.x), "R", dim_z)
        y = _finite_vector(model.residual(z, z_pred), "residual(z, z_pred)", dim_z)
        return z, z_pred, H, R, y

    def update(self, z: ArrayLike, model: MeasurementModel) -> UpdateResult:  # type: ignore[override]
        """Gated EKF update with measurement ``z`` of model ``model``.

        ``y = residual(z, h(x))``, ``S = H P H^T + R``, ``NIS = y^T S^-1 y`` (Cholesky solve;
        with the model's ``gate_R(x)`` in S when it has one). If
        ``NIS`` exceeds the gate the state is left unchanged; otherwise filterpy's update runs:
        ``K = P H^T S^-1``, ``x = x + K y``, ``P = (I - K H) P (I - K H)^T + K R K^T``; then yaw
        is wrapped and ``P`` symmetrized.

        Parameters
        ----------
        z : array_like (dim_z,)
            The measurement.
        model : MeasurementModel
            Provides ``h``, ``H``, ``R`` (or ``R_at``) and ``residual``.

        Returns
        -------
        UpdateResult
        """
        z, z_pred, H, R, y = self.innovation(z, model)
        dim_z = z.shape[0]
        S = H @ self.P @ H.T + self.gate_noise(model, R)
        try:
            nis = float(y @ cho_solve(cho_factor(S), y))
        except LinAlgError:
            raise ValueError("innovation covariance S = H P H^T + R is not positive definite") from None
        threshold = gate_threshold(self.gate_probability, dim_z)
        if nis > threshold:
            return UpdateResult(nis=nis, accepted=False, dim_z=dim_z, threshold=threshold)
        self.dim_z = dim_z
        super().update(z, lambda x: H, lambda x: z_pred, R=R, residual=lambda a, b: y)
        self.x[2] = wrap_angle(self.x[2])
        self.P = 0.5 * (self.P + self.P.T)
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        return UpdateResult(nis=nis, accepted=True, dim_z=dim_z, threshold=threshold)

    def gate_noise(self, model: MeasurementModel, R: Array) -> Array:
        """The noise the NIS gate uses at ``x``: the model's ``gate_R(x)`` (checked) when it
        has one, else ``R`` (the model's noise there, from :meth:`innovation`)."""
        gate_R = getattr(model, "gate_R", None)
        return R if not callable(gate_R) else _covariance(gate_R(self.x), "gate_R(x)", len(R))

    def snapshot(self) -> tuple[Array, ...]:
        """Copies of ``x`` and ``P`` (a subclass adds its own state), for :meth:`restore`."""
        return self.x.copy(), self.P.copy()

    def restore(self, state: tuple[Array, ...]) -> None:
        """Back to a :meth:`snapshot` (e.g. an update undone)."""
        self.x, self.P = state[0].copy(), state[1].copy()

    def nees(self, true_pose: ArrayLike) -> float:
        """Normalized estimation error squared ``e^T P^-1 e``, ``e = true_pose - x`` (yaw wrapped)."""
        e = pose_residual(_finite_vector(true_pose, "true_pose", 3), self.x)
        return float(e @ cho_solve(cho_factor(self.P), e))


def chi2_band(dof: int, n: int, prob: float = 0.95) -> tuple[float, float]:
    """Two-sided band for the average of ``n`` independent chi2(``dof``) values (NEES or NIS).

    The sum of n independent chi2(d) values is chi2(n d), so the average lies in
    ``chi2.ppf([(1 - prob) / 2, (1 + prob) / 2], n * dof) / n`` with probability ``prob``
    (prob = 0.95 gives ``chi2.ppf([0.025, 0.975], n d) / n``).

    Parameters
    ----------
    dof : int
        Degrees of freedom of each value (3 for the pose NEES, dim_z for the NIS).
    n : int
        Number of independent values averaged (e.g. Monte Carlo runs at one time step).
    prob : float
        Coverage of the band.

    Returns
    -------
    (float, float)
        Lower and upper bound of the average.
    """
    if dof < 1 or n < 1 or not 0.0 < prob < 1.0:
        raise ValueError(f"need dof >= 1, n >= 1, 0 < prob < 1; got {dof}, {n}, {prob}")
    return _chi2_band(int(dof), int(n), float(prob))


@lru_cache(maxsize=256)
def _chi2_band(dof: int, n: int, prob: float) -> tuple[float, float]:
    """:func:`chi2_band`'s quantiles (cached: the divergence monitor asks every step)."""
    lo, hi = chi2.ppf([(1.0 - prob) / 2.0, (1.0 + prob) / 2.0], n * dof) / n
    return float(lo), float(hi)


def numerical_jacobian(fun: Callable[[Array], ArrayLike], x: ArrayLike, eps: float = 1e-6,
                       residual: Callable[[Array, Array], ArrayLike] | None = None) -> Array:
    """Central finite-difference Jacobian ``d fun / d x``, shape (dim_f, dim_x).

    ``residual(a, b)`` (default ``a - b``) forms the differences, e.g. :func:`pose_residual`
    when ``fun`` returns a pose, to check a measurement model's ``H`` against its ``h``.
    """
    x = np.asarray(x, dtype=np.float64)
    diff = residual or np.subtract
    cols = []
    for i in range(x.shape[0]):
        dx = np.zeros_like(x)
        dx[i] = eps
        cols.append(np.asarray(diff(fun(x + dx), fun(x - dx)), dtype=np.float64) / (2.0 * eps))
    return np.stack(cols, axis=-1)
