"""The motion model F for many poses at once: a vectorised unicycle step and process noise.

A particle filter moves thousands of poses per step; ``UnicycleModel.predict`` takes one.
:func:`unicycle_step` is the same exact arc integration over an (N, 3) array::

    yaw' = yaw + w dt
    x'   = x + v / w (sin(yaw') - sin(yaw))        (x + v dt cos(yaw + w dt / 2) as w -> 0)
    y'   = y - v / w (cos(yaw') - cos(yaw))        (y + v dt sin(yaw + w dt / 2) as w -> 0)

:func:`predict_particles` applies a motion model F to particles: a model's own
``predict_many`` when it has one, else :func:`unicycle_step` when F is a unicycle of step
``dt`` (:func:`is_unicycle` checks it against ``F.predict`` on a few probe poses), else one
``F.predict`` per particle. :func:`sample_body_noise` draws the process noise Q in the
body frame (along, cross, heading) and rotates it into the world frame at each particle.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array, wrap_angle

__all__ = ["is_unicycle", "move_particles", "predict_particles", "sample_body_noise", "unicycle_step"]

_SMALL_W = 1e-6  # as envs.motion_model: below it the arc's second-order expansion
_PROBES = np.array([[0.3, -1.2, 2.9], [-4.0, 2.5, -0.7], [1.0, 1.0, 0.0], [0.0, 0.0, -3.1]])
_PROBE_U = np.array([[0.6, 0.4], [0.5, -1e-9], [-0.3, -0.9], [0.8, 1.0]])


def unicycle_step(X: ArrayLike, u: ArrayLike, dt: float) -> Array:
    """F(X, U) for particles ``X`` (N, 3) under one control ``u`` (2,) or one per
    particle (N, 2), held for ``dt`` seconds; headings wrapped to (-pi, pi]."""
    X = np.asarray(X, dtype=np.float64)
    u = np.broadcast_to(np.asarray(u, dtype=np.float64), (len(X), 2))
    yaw, v, w = X[:, 2], u[:, 0], u[:, 1]
    yaw2 = yaw + w * dt
    small = np.abs(w) < _SMALL_W
    w_safe = np.where(small, 1.0, w)
    r = v / w_safe
    mid = yaw + 0.5 * w * dt
    dx = np.where(small, v * dt * np.cos(mid), r * (np.sin(yaw2) - np.sin(yaw)))
    dy = np.where(small, v * dt * np.sin(mid), -r * (np.cos(yaw2) - np.cos(yaw)))
    return np.column_stack([X[:, 0] + dx, X[:, 1] + dy, wrap_angle(yaw2)])


def is_unicycle(motion_model: Any) -> bool:
    """Whether ``motion_model.predict`` equals :func:`unicycle_step` with the model's ``dt``
    (to 1e-9 on a few probe poses and controls, both sides of the small-w expansion)."""
    dt = getattr(motion_model, "dt", None)
    if not (isinstance(dt, (int, float)) and dt > 0):
        return False
    fast = [unicycle_step(p[None], u, float(dt))[0] for p, u in zip(_PROBES, _PROBE_U)]
    slow = [motion_model.predict(p, u) for p, u in zip(_PROBES, _PROBE_U)]
    d = np.subtract(fast, slow)
    d[:, 2] = wrap_angle(d[:, 2])
    return bool(np.all(np.abs(d) < 1e-9))


def predict_particles(motion_model: Any, X: ArrayLike, u: ArrayLike,
                      unicycle: bool | None = None) -> Array:
    """F(X, U) for particles (N, 3): the model's ``predict_many`` when it has one, else the
    vectorised unicycle when ``unicycle`` (None: ask :func:`is_unicycle`), else a loop."""
    X = np.asarray(X, dtype=np.float64)
    if hasattr(motion_model, "predict_many"):
        return np.asarray(motion_model.predict_many(X, u), dtype=np.float64)
    if is_unicycle(motion_model) if unicycle is None else unicycle:
        return unicycle_step(X, u, float(motion_model.dt))
    return np.array([motion_model.predict(x, u) for x in X]).reshape(-1, 3)


def sample_body_noise(yaw: ArrayLike, Q_body: ArrayLike, rng: np.random.Generator) -> Array:
    """World-frame draws (N, 3) of ``T(yaw_i) e_i`` with ``e_i ~ N(0, Q_body)`` (body frame:
    along, cross, heading) at the headings ``yaw`` (N,)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    Q_body = np.asarray(Q_body, dtype=np.float64)
    e = rng.multivariate_normal(np.zeros(3), Q_body, size=len(yaw), method="eigh")
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([c * e[:, 0] - s * e[:, 1], s * e[:, 0] + c * e[:, 1], e[:, 2]])


def move_particles(motion_model: Any, X: ArrayLike, u: ArrayLike, Q_body: ArrayLike,
                   rng: np.random.Generator, unicycle: bool | None = None,
                   Q_extra: ArrayLike | None = None) -> Array:
    """``X_i = F(X_i, u) + T(yaw_i) e_i``, ``e_i ~ N(0, Q_body)``, plus a world-frame draw of
    ``N(0, Q_extra)`` each (a contact's, isotropic in x, y); headings wrapped. (N, 3)."""
    X = predict_particles(motion_model, X, u, unicycle)
    X += sample_body_noise(X[:, 2], Q_body, rng)
    if Q_extra is not None:
        X += rng.multivariate_normal(np.zeros(3), np.asarray(Q_extra, dtype=np.float64),
                                     size=len(X), method="eigh")
    return np.column_stack([X[:, :2], wrap_angle(X[:, 2])])

