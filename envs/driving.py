"""The pure-pursuit steering law, shared by the recorded drives (:class:`envs.datasets.PurePursuit`)
and the agents (:func:`agents.scripted.pure_pursuit`).

Pure pursuit steers on the arc through the robot and a "carrot" point ahead on the path: with
``alpha`` the carrot's bearing from the heading and ``L`` the look-ahead distance, the arc's
curvature is ``kappa = 2 sin(alpha) / L``, so at forward speed ``v`` the turn rate is
``w = v kappa`` (clipped to ``[-w_max, w_max]``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import wrap_angle

__all__ = ["bearing", "pursuit_turn_rate"]


def bearing(pose: ArrayLike, point: ArrayLike) -> float:
    """Bearing ``alpha`` (rad, in (-pi, pi]) of ``point`` (2,) seen from ``pose`` [x, y, yaw]."""
    pose, point = np.asarray(pose, dtype=np.float64), np.asarray(point, dtype=np.float64)
    return float(wrap_angle(np.arctan2(point[1] - pose[1], point[0] - pose[0]) - pose[2]))


def pursuit_turn_rate(alpha: float, speed: float, lookahead: float, w_max: float) -> float:
    """``w = clip(2 speed sin(alpha) / lookahead, -w_max, w_max)`` (rad/s)."""
    return float(np.clip(2.0 * speed * np.sin(alpha) / lookahead, -w_max, w_max))
