"""Planar pose geometry shared by the env and the localization toolkit: the one copy.

A pose is ``theta = [x, y, yaw]`` (metres, metres, radians, yaw in (-pi, pi]). Pose errors
are expressed either in the world frame or in the robot's body frame ``[along, cross,
heading]``; ``T(yaw)`` rotates body-frame vectors into the world frame::

    T(yaw) = [[cos yaw, -sin yaw, 0],
              [sin yaw,  cos yaw, 0],
              [0,        0,       1]]

This module imports only numpy, so :mod:`envs` and every layer of :mod:`localization` can
use it without importing each other.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Array",
    "MotionModel",
    "body_rotation",
    "body_to_world",
    "cov_to_triu",
    "pose_residual",
    "position_std",
    "to_body",
    "triu_to_cov",
    "wrap_angle",
]

Array = NDArray[np.float64]
_TRIU = np.triu_indices(3)


class MotionModel(Protocol):
    """What the filters need from a motion model F(theta, U) (e.g.
    ``envs.motion_model.UnicycleModel``): the next pose and its Jacobians."""

    def predict(self, pose: ArrayLike, u: ArrayLike) -> Array: ...
    def jacobian_pose(self, pose: ArrayLike, u: ArrayLike) -> Array: ...
    def jacobian_control(self, pose: ArrayLike, u: ArrayLike) -> Array: ...


def wrap_angle(a: ArrayLike) -> Array:
    """Wrap angles to (-pi, pi]."""
    a = np.asarray(a, dtype=np.float64)
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def pose_residual(a: ArrayLike, b: ArrayLike) -> Array:
    """Pose difference ``a - b`` with the yaw component wrapped to (-pi, pi], shape (3,)."""
    d = np.subtract(a, b).astype(np.float64)
    d[2] = wrap_angle(d[2])
    return d


def body_rotation(yaw: float) -> Array:
    """T(yaw), the (3, 3) rotation taking body-frame pose errors to the world frame."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def to_body(errors: ArrayLike, yaw: ArrayLike) -> Array:
    """Rotate world-frame pose errors (n, 3) into the body frame at headings ``yaw`` (n,).

    Returns ``[along, cross, heading]`` (n, 3): ``T(yaw)^T e`` with the heading wrapped.
    """
    e = np.asarray(errors, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([c * e[:, 0] + s * e[:, 1], -s * e[:, 0] + c * e[:, 1],
                            wrap_angle(e[:, 2])])


def body_to_world(C_body: ArrayLike, yaw: float) -> Array:
    """``T(yaw) C_body T(yaw)^T``: a body-frame pose covariance (3, 3) in the world frame."""
    T = body_rotation(yaw)
    return T @ np.asarray(C_body, dtype=np.float64) @ T.T


def cov_to_triu(P: ArrayLike) -> NDArray[np.float32]:
    """The upper triangle (6,) of a (3, 3) covariance, row by row, float32."""
    return np.asarray(P, dtype=np.float64)[_TRIU].astype(np.float32)


def triu_to_cov(v: ArrayLike) -> Array:
    """Inverse of :func:`cov_to_triu`: (..., 6) -> (..., 3, 3) float64."""
    v = np.asarray(v, dtype=np.float64)
    if v.shape[-1] != 6:
        raise ValueError(f"need (..., 6) upper-triangle entries, got shape {v.shape}")
    P = np.zeros(v.shape[:-1] + (3, 3))
    P[..., _TRIU[0], _TRIU[1]] = v
    P[..., _TRIU[1], _TRIU[0]] = v
    return P


def position_std(P: ArrayLike) -> float:
    """The largest standard deviation (m) of a pose covariance's position block ``P[:2, :2]``
    (0 if rounding makes it negative)."""
    P = np.asarray(P, dtype=np.float64)
    return float(np.sqrt(max(np.linalg.eigvalsh(P[:2, :2])[-1], 0.0)))
