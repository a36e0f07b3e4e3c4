"""The known motion model F(theta, U): unicycle kinematics over one env step.

The pose is ``theta = [x, y, yaw]`` (metres, metres, radians, yaw in (-pi, pi])
and the control ``U = [v, w]`` (commanded linear m/s and angular rad/s
velocity), held constant for ``dt`` seconds. With exact integration of the
unicycle (an arc of radius v / w)::

    yaw' = yaw + w dt
    x'   = x + v / w (sin(yaw') - sin(yaw))          (x + v dt cos(yaw) as w -> 0)
    y'   = y - v / w (cos(yaw') - cos(yaw))          (y + v dt sin(yaw) as w -> 0)

``F_x = d predict / d theta`` (3 x 3) and ``F_u = d predict / d U`` (3 x 2)
are the Jacobians an extended Kalman filter needs.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from localization._validation import check_array, check_real
from localization.geometry import wrap_angle

_SMALL_W = 1e-6


def _check(pose: ArrayLike, u: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    return (check_array(pose, "pose", shape=(3,), what="[x, y, yaw]"),
            check_array(u, "u", shape=(2,), what="[v, w] (the control)"))


class UnicycleModel:
    """Unicycle kinematics F(theta, U) for a control held over ``dt`` seconds.

    Parameters
    ----------
    dt : float
        Duration of one step in seconds (the env's control period).
    """

    def __init__(self, dt: float) -> None:
        self.dt = check_real(dt, "dt", low=0.0, low_open=True)

    def __repr__(self) -> str:
        return f"UnicycleModel(dt={self.dt})"

    def predict(self, pose: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Return F(theta, U), the pose after one step, shape (3,)."""
        (x, y, yaw), (v, w) = _check(pose, u)
        dt = self.dt
        yaw2 = yaw + w * dt
        if abs(w) < _SMALL_W:
            # second-order expansion of the arc in w keeps predict smooth across w = 0
            c, s = np.cos(yaw + 0.5 * w * dt), np.sin(yaw + 0.5 * w * dt)
            x2, y2 = x + v * dt * c, y + v * dt * s
        else:
            r = v / w
            x2 = x + r * (np.sin(yaw2) - np.sin(yaw))
            y2 = y - r * (np.cos(yaw2) - np.cos(yaw))
        return np.array([x2, y2, wrap_angle(yaw2)])

    def jacobian_pose(self, pose: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Return F_x = d F / d theta, shape (3, 3)."""
        (_, _, yaw), (v, w) = _check(pose, u)
        dt = self.dt
        yaw2 = yaw + w * dt
        F = np.eye(3)
        if abs(w) < _SMALL_W:
            m = yaw + 0.5 * w * dt
            F[0, 2] = -v * dt * np.sin(m)
            F[1, 2] = v * dt * np.cos(m)
        else:
            r = v / w
            F[0, 2] = r * (np.cos(yaw2) - np.cos(yaw))
            F[1, 2] = r * (np.sin(yaw2) - np.sin(yaw))
        return F

    def jacobian_control(self, pose: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Return F_u = d F / d U, shape (3, 2)."""
        (_, _, yaw), (v, w) = _check(pose, u)
        dt = self.dt
        yaw2 = yaw + w * dt
        B = np.zeros((3, 2))
        B[2, 1] = dt
        if abs(w) < _SMALL_W:
            m = yaw + 0.5 * w * dt
            B[0, 0], B[1, 0] = dt * np.cos(m), dt * np.sin(m)
            B[0, 1] = -0.5 * v * dt * dt * np.sin(m)
            B[1, 1] = 0.5 * v * dt * dt * np.cos(m)
        else:
            ds, dc = np.sin(yaw2) - np.sin(yaw), np.cos(yaw2) - np.cos(yaw)
            B[0, 0], B[1, 0] = ds / w, -dc / w
            B[0, 1] = -v * ds / w**2 + v / w * np.cos(yaw2) * dt
            B[1, 1] = v * dc / w**2 + v / w * np.sin(yaw2) * dt
        return B
