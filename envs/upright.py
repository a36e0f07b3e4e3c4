"""Keeping the robot on its wheels: a restoring torque past a tilt no driving reaches.

A vehicle's shove once flipped the robot on its back (tuning cities 13-16, reset seed 3000080
of the robustness benchmark's traffic rows, in all four), and it then drove blind, its
wheels turning it the wrong way. Past :data:`UPRIGHT_TILT` a torque (:func:`upright_torque`)
rights it; below (all of normal driving, ~0.15 rad) the physics is untouched, so every
trajectory and image without such a shove is what it was without the torque.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["TIPPED_OVER_TILT", "UPRIGHT_DAMPING", "UPRIGHT_STIFFNESS", "UPRIGHT_TILT",
           "Upright", "upright_torque"]

#: rad of tilt (the body's up axis from the vertical) beyond which the robot is on its side or
#: back (``info["tipped_over"]``); the upright torque rights it (held-out cities 21-22, 400
#: traffic episodes: one tilted past it for a moment, righted, and reached its goal)
TIPPED_OVER_TILT = 1.0
#: rad of tilt from which the upright torque acts (normal driving stays far below: ~0.15 rad)
UPRIGHT_TILT = 0.5
#: N m per rad of tilt past UPRIGHT_TILT, and N m s per rad/s of roll and pitch rate
UPRIGHT_STIFFNESS, UPRIGHT_DAMPING = 20.0, 1.0
_COS_UPRIGHT = math.cos(UPRIGHT_TILT)


def upright_torque(xmat: NDArray[np.float64], w_body: NDArray[np.float64]) -> NDArray[np.float64]:
    """World torque (3,) that rights the robot once tilted past :data:`UPRIGHT_TILT`: a spring
    ``UPRIGHT_STIFFNESS (tilt - UPRIGHT_TILT)`` about the axis that rights it, damped by
    ``UPRIGHT_DAMPING`` on the roll and pitch rate; zero below that tilt.

    Parameters
    ----------
    xmat : (9,) the body's rotation matrix (``data.xmat``), row-major.
    w_body : (3,) its angular velocity in the body frame (the free joint's ``qvel[3:6]``).
    """
    R = np.asarray(xmat, dtype=np.float64).reshape(3, 3)
    up = R[:, 2]
    tilt = float(np.arccos(np.clip(up[2], -1.0, 1.0)))
    if tilt <= UPRIGHT_TILT:
        return np.zeros(3)
    axis = np.array([up[1], -up[0], 0.0])  # up x z: turning about it brings up to z
    norm = float(np.linalg.norm(axis))
    axis = axis / norm if norm > 1e-9 else np.array([1.0, 0.0, 0.0])  # upside down: any axis
    w = R @ np.asarray(w_body, dtype=np.float64)
    w[2] = 0.0  # the heading's turn is the wheels' business
    return UPRIGHT_STIFFNESS * (tilt - UPRIGHT_TILT) * axis - UPRIGHT_DAMPING * w


class Upright:
    """The robot body's tilt and its upright torque in one model (body ``"robot"`` on the free
    joint ``"root"``)."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self._body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot")
        root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "root")
        self._spin = slice(model.jnt_dofadr[root] + 3, model.jnt_dofadr[root] + 6)
        self._on = False  # a torque is in data.xfrc_applied

    def tilt(self, data: mujoco.MjData) -> float:
        """Angle (rad) between the body's up axis and the vertical: 0 upright, pi on its back."""
        return math.acos(min(max(float(data.xmat[self._body, 8]), -1.0), 1.0))

    def apply(self, data: mujoco.MjData) -> None:
        """Set ``data.xfrc_applied``'s torque for the current tilt (before each ``mj_step``);
        while upright and no torque is on, a single comparison."""
        b = self._body
        if data.xmat[b, 8] > _COS_UPRIGHT and not self._on:
            return
        data.xfrc_applied[b, 3:] = torque = upright_torque(data.xmat[b], data.qvel[self._spin])
        self._on = bool(torque.any())
