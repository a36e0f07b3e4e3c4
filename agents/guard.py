"""A guard against the wall the belief does not see: the image's own pose estimate vetoes
forward motion into a building.

A robot pushed off its lane keeps a belief that trusts its old lane for a while: the
measurement noise R is wide (the calibration covers psi*'s slowly varying errors), so the
belief follows the new images a few centimetres a step, while psi* of each image, the pose
the image alone says, is already near the truth (docs/benchmarks.md section 11, stop 72). A
pilot steering on the belief then drives into a wall it does not know is there.

:class:`ImageGuard` checks each command against the map from where the latest image puts the
robot: the command U = [v, w], held for ``horizon`` seconds from the image's pose
``info["image_pose"]`` (published by ``BeliefWrapper(..., image_pose=True)``), must not
bring the robot's disc (``ROBOT_RADIUS + margin``) closer to a building than it already is
where that clearance is short. If it would, the pilot does not drive forward this step (v = 0;
it may still turn). The belief itself is not touched. An image pose farther than ``radius``
from the belief (an aliased image) or inside a building is ignored.

A veto can hold forever: a vetoed robot does not move, so it sends the same command again.
Passing a building corner 0.56 m off (inside ``ROBOT_RADIUS + margin``) with a right belief,
every forward rollout dips a few centimetres nearer the corner, and one robot stood 520 steps
(tuning city 13, docs/benchmarks.md section 11, stop 75). With ``patience`` set, after that
many consecutive vetoes the guard yields: it lets ``yield_steps`` forward commands through
(the bumper and the pilot's back-off still act), then guards again. With ``agree`` set it
yields only while the image pose lies within ``agree`` metres of the belief mean: a belief
that agrees with its image planned around the wall it is passing, while a pushed belief a
metre off, the case the guard is for, is still guarded.

Near a wall psi* of single images alternates between a few decimetres off the truth and a metre
or more off (tuning city 14, docs/benchmarks.md section 11, stop 76), so a guard that looks at
the latest image only lets the robot move on the bad frames. With ``memory`` set, a command is
also checked from each of the last ``memory`` steps' image poses, each carried forward to now
by the known motion model F with the commands sent since (:meth:`ImageGuard.remember`: a fix a
few steps old plus odometry); any of them can veto. A contact clears them (the robot did not
move as commanded). It is an option, off in the robustness rows: with ``memory=5`` the EKF
rows' pushed contacts fell on tuning cities 13-14 and rose held out (0.065 -> 0.150 contact
steps per episode), as the robot waited longer next to the wall it then scraped.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from envs.motion_model import UnicycleModel
from envs.robot import ROBOT_RADIUS
from localization._validation import check_int, check_real
from localization.geometry import Array

__all__ = ["GUARD_HORIZON", "GUARD_MARGIN", "GUARD_RADIUS", "ImageGuard", "rollout"]

#: s, how far ahead a command is checked
GUARD_HORIZON = 0.5
#: m, clearance kept beyond the robot's disc: psi* cannot read a robot closer to a wall than
#: the map's images were (POSE_MARGIN, 0.32 m), and near a wall it reads 0.3-0.5 m farther out
#: than the truth, so the guard must act while psi* is still within that reach (0.05 m missed
#: every wall on tuning city 14; 0.4 m halved the pushed contacts on tuning cities 13-14)
GUARD_MARGIN = 0.4
#: m, image poses farther than this from the belief are taken as aliased and ignored
GUARD_RADIUS = 3.0


def rollout(pose: Array, u: Array, horizon: float, n: int) -> Array:
    """Positions (n, 2) of the known motion model F (the unicycle, exact arcs) from ``pose``
    [x, y, yaw] under U = [v, w] held for ``horizon`` seconds, at n equal times after the
    start."""
    F, out = UnicycleModel(horizon / n), []
    for _ in range(n):
        pose = F.predict(pose, u)
        out.append(pose[:2])
    return np.array(out)


class ImageGuard:
    """Veto forward commands that would take the image's pose into a building.

    Parameters
    ----------
    city : envs.scene.City
        The map (``env.unwrapped.city``).
    horizon : float — seconds a command is held in the check (> 0).
    margin : float — metres of clearance beyond ``ROBOT_RADIUS`` (>= 0).
    radius : float — image poses farther than this (m) from the belief are ignored (> 0).
    n_points : int — points of the rolled-out arc that are checked (>= 1).
    patience : int or None — consecutive vetoes after which it yields (>= 1); None: never.
    yield_steps : int — steps it then lets forward commands through (>= 1).
    agree : float or None — metres: yield only while the image pose lies this close to the
        belief mean (> 0); None: whatever the belief.
    memory : int — earlier steps' image poses also checked, carried forward by F (>= 0; 0:
        the latest image only).
    dt : float — seconds per step, to carry them forward (the env's ``dt``, > 0).
    """

    def __init__(self, city: Any, horizon: float = GUARD_HORIZON, margin: float = GUARD_MARGIN,
                 radius: float = GUARD_RADIUS, n_points: int = 5, patience: int | None = None,
                 yield_steps: int = 10, agree: float | None = None, memory: int = 0,
                 dt: float = 0.1) -> None:
        self.city = city
        self.horizon = check_real(horizon, "horizon", low=0.0, low_open=True)
        self.margin = check_real(margin, "margin", low=0.0)
        self.radius = check_real(radius, "radius", low=0.0, low_open=True)
        self.n_points = check_int(n_points, "n_points", low=1)
        self.patience = None if patience is None else check_int(patience, "patience", low=1)
        self.yield_steps = check_int(yield_steps, "yield_steps", low=1)
        self.agree = None if agree is None else check_real(agree, "agree", low=0.0,
                                                           low_open=True)
        self.memory = check_int(memory, "memory", low=0)
        self.F = UnicycleModel(check_real(dt, "dt", low=0.0, low_open=True))
        self.vetoes = 0
        self.reset()

    def reset(self) -> None:
        """Forget the run of vetoes, any yield and the remembered image poses (call between
        episodes)."""
        self._run = 0  # consecutive vetoes
        self._yielding = 0  # steps of yielding left
        self._poses: list[Array | None] = []  # earlier image poses carried to now, oldest first

    def blocks(self, u: Array, mean: Array, info: Mapping[str, Any] | None) -> bool:
        """Whether the forward command ``u`` (2,) should not be driven, from the belief mean
        (3,) and the step's ``info`` (its ``image_pose``; no veto without one), or from a
        remembered image pose (``memory``)."""
        if info is None or u[0] <= 0:
            return False
        if "image_pose" not in info:
            raise KeyError("the image guard needs info['image_pose']: wrap the env in "
                           "BeliefWrapper(..., image_pose=True)")
        poses = [_image_pose(info), *self._poses]
        return any(self._blocks_from(pose, u, mean) for pose in poses if pose is not None)

    def remember(self, u: Array, info: Mapping[str, Any] | None) -> None:
        """After the command ``u`` (2,) is sent (whoever chose it): keep this step's image
        pose among the last ``memory`` and carry each one step forward by F; a contact
        (``info["collision"]``) or a step without ``info`` forgets them."""
        if self.memory == 0:
            return
        if info is None or info.get("collision"):
            self._poses = []
            return
        u = np.asarray(u, dtype=np.float64)
        poses = [*self._poses, _image_pose(info)][-self.memory:]
        self._poses = [None if p is None else self.F.predict(p, u) for p in poses]

    def _blocks_from(self, pose: Array, u: Array, mean: Array) -> bool:
        """Whether ``u`` held for ``horizon`` from the image pose ``pose`` (3,) runs the disc
        into a building where its clearance is short (an image pose far from the belief
        ``mean`` or inside a building: no)."""
        if np.hypot(*(pose[:2] - mean[:2])) > self.radius:
            return False
        start = float(self.city.clearance(pose[None, :2])[0])
        if start < 0:
            return False
        ahead = float(self.city.clearance(rollout(pose, u, self.horizon, self.n_points)).min())
        return ahead < ROBOT_RADIUS + self.margin and ahead < start

    def filter(self, u: Array, mean: Array, info: Mapping[str, Any] | None) -> Array:
        """``u`` with v = 0 when :meth:`blocks` (counted in ``vetoes``), unless it yields."""
        if self._yielding > 0:
            self._yielding -= 1
            return u
        if not self.blocks(u, mean, info):
            self._run = 0
            return u
        self.vetoes += 1
        self._run += 1
        if self.patience is not None and self._run >= self.patience and self._agrees(mean, info):
            self._run, self._yielding = 0, self.yield_steps
        u = u.copy()
        u[0] = 0.0
        return u

    def _agrees(self, mean: Array, info: Mapping[str, Any]) -> bool:
        """Whether the latest image pose lies within ``agree`` of the belief mean (True
        without ``agree``; False without a usable image pose: a veto from memory alone)."""
        if self.agree is None:
            return True
        pose = _image_pose(info)
        return pose is not None and bool(np.hypot(*(pose[:2] - mean[:2])) <= self.agree)


def _image_pose(info: Mapping[str, Any]) -> Array | None:
    """``info["image_pose"]`` as a finite pose (3,), or None (missing, NaN, malformed)."""
    pose = info.get("image_pose")
    if pose is None:
        return None
    pose = np.asarray(pose, dtype=np.float64)
    return pose if pose.shape == (3,) and np.all(np.isfinite(pose)) else None
