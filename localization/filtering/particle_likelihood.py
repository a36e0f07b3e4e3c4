"""The measurement likelihood of many pose hypotheses at once (the particle belief's weights).

The squared Mahalanobis distance ``d2_i`` of an image's measurement at each pose ``X_i``,
in one batched GSE query, with the localizer's three measurement models (R as in
``localizer.measurement_model``, inflated by the calibrated consistency factors a):

- "representation": ``e_i = H_i^-1 (r*(w) - R*(theta_i))``, ``H_i = dR*/dtheta`` at
  ``theta_i``, ``d2_i = e_b^T R^-1 e_b`` with ``e_b = T(yaw_i)^T e_i`` and R the body-frame
  pose noise of the model: the same as ``y^T (H T R T^T H^T)^-1 y`` (the Jacobian
  determinant is left out: a near-singular H would otherwise lift far particles above the
  truth);
- "pose": ``e_b = T(yaw_i)^T wrap(psi*(w) - theta_i)``, ``d2_i = e_b^T R^-1 e_b``;
- "features": ``d2_i = (w - Phi*(theta_i))^T R^-1 (w - Phi*(theta_i))``.

The log-likelihood is ``log L_i = -0.5 min(d2_i, gate)``, ``gate = chi2.ppf(gate_probability,
dof)``: outliers are capped at the gate (an aliased image moves every weight alike) and
poses where the GSE maps are undefined (NaN: out of the training domain) get that floor,
never NaN.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import chi2

from localization._validation import check_choice
from localization.filtering.map_contact import FreeSpace, free_at
from localization.filtering.measurement_noise import inflate
from localization.geometry import Array, to_body

__all__ = ["MEASUREMENTS", "UNMAPPED", "ParticleLikelihood", "capped_log_likelihood",
           "check_unmapped", "unmapped_d2"]

MEASUREMENTS = ("pose", "features", "representation")
#: what a particle where the maps are undefined gets (``ParticleFilter(unmapped=...)``)
UNMAPPED = ("floor", "typical")


def capped_log_likelihood(d2: Array, gate: float, unmapped: Array | None = None) -> Array:
    """``log L_i = -0.5 min(d2_i, gate)`` (N,), never NaN: where ``d2`` is NaN (no map at
    that pose) ``-0.5 gate``, or ``-0.5 unmapped_i`` where ``unmapped`` (N,) is given."""
    floor = np.full_like(d2, gate) if unmapped is None else np.minimum(unmapped, gate)
    return -0.5 * np.where(np.isnan(d2), floor, np.minimum(d2, gate))


def unmapped_d2(free_space: FreeSpace, X: Array, dof: int) -> Array:
    """``unmapped="typical"``'s d2 (N,) for poses ``X`` (N, 3) where the maps are undefined:
    ``dof`` (the chi-square mean: the map says nothing there) where ``free_space`` has the
    street, inf (the gate's floor) inside a building."""
    return np.where(free_at(free_space, X[:, :2], 0.0), float(dof), np.inf)


def check_unmapped(unmapped: object, free_space: FreeSpace | None) -> str:
    """``unmapped`` if one of :data:`UNMAPPED` ("typical" needs ``free_space``), else a
    ValueError naming it."""
    choice = check_choice(unmapped, "unmapped", UNMAPPED)
    if choice == "typical" and free_space is None:
        raise ValueError("unmapped='typical' needs free_space (the city's free_mask)")
    return choice


class ParticleLikelihood:
    """Batched measurement likelihood (see the module docstring).

    Parameters
    ----------
    localizer : AppearanceLocalizer
        Fitted, with its noise model.
    measurement : {"representation", "pose", "features"}
    alpha : ndarray (3,)
        Body-frame inflation of R (the features model takes their mean).
    gate_probability : float in (0, 1)

    Attributes
    ----------
    R : ndarray (3, 3), or (m, m) for "features"
    gate : float
        The cap of ``d2``.
    """

    def __init__(self, localizer: Any, measurement: str, alpha: Array,
                 gate_probability: float) -> None:
        if measurement not in MEASUREMENTS:
            raise ValueError(f"unknown measurement {measurement!r}; choose one of {MEASUREMENTS}")
        if not 0.0 < gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1), got {gate_probability}")
        self.localizer, self.measurement = localizer, measurement
        m = len(localizer.regressor_.w_mean_)
        if measurement == "features":
            R, dof = localizer.noise_["features"] * float(np.mean(alpha)), m
        else:
            R, dof = inflate(localizer.noise_[measurement], alpha), 3
        self.R, self.gate = R, float(chi2.ppf(gate_probability, dof))
        self._R_inv = np.linalg.inv(R)

    def measure(self, w: Array) -> Array:
        """The measurement z of the features ``w`` (m,) (NaN out of the training domain)."""
        return self.localizer.measure(w, self.measurement)

    def distances(self, z: Array, X: ArrayLike) -> Array:
        """Squared Mahalanobis distances d2 (N,) of the measurement ``z`` at the poses
        ``X`` (N, 3); NaN where the maps are undefined."""
        loc, reg = self.localizer, self.localizer.regressor_
        X = np.asarray(X, dtype=np.float64)
        if self.measurement == "features":
            e = z - reg.predict_features(loc.to_model(X))
            return np.einsum("ni,ij,nj->n", e, self._R_inv, e)
        if self.measurement == "pose":
            e = z[None] - X
        else:
            Rstar, H = reg.embed_pose_with_jacobian(loc.to_model(X))
            e = np.full_like(X, np.nan)
            ok = np.all(np.isfinite(H), axis=(1, 2)) & np.all(np.isfinite(z))
            ok[ok] &= np.abs(np.linalg.det(H[ok])) > 1e-12
            e[ok] = np.linalg.solve(H[ok], (z[None] - Rstar[ok])[..., None])[..., 0]
        eb = to_body(e, X[:, 2])
        return np.einsum("ni,ij,nj->n", eb, self._R_inv, eb)

    def log_likelihood(self, z: Array, X: ArrayLike) -> Array:
        """``log L_i = -0.5 min(d2_i, gate)`` (N,): never NaN."""
        return capped_log_likelihood(self.distances(z, X), self.gate)
