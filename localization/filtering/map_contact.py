"""What a contact tells the belief: the odometry of that step is in doubt, and a bump where
the map has room contradicts the belief.

A robot pressed against an obstacle (a waiting vehicle, a wall) is commanded forward but does
not move: predicting with the commanded control runs the belief ahead by the commanded step
each contact step, and once it is metres ahead the images are gated as outliers and nothing
brings it back (tuning city 12, a route drive among vehicles: 206 contact steps, 11.95 m of
odometry error on them, the belief lost 15 steps into the contact). :func:`blocked_motion`
predicts a contact step as blocked instead: no translation (the turn kept), with the
commanded translation and turn as one standard deviation of what may still have happened.

A robot knows its map (the city's buildings) and feels a contact (a bumper,
``info["collision"]``). A contact while the belief's mean has free space all around it
cannot have happened where the belief says the robot is: the belief is wrong, though it may
still say "doubtful" (coasting with a narrow P) and steer on into the wall.
:class:`~localization.filtering.belief.BeliefFilter` calls the belief "lost" for ``CONTACT_LOST_STEPS`` steps after such a contact (an agent stops
and looks), then lets it drive on; a restart still on trial too. A belief that is not
"tracking" and bumps into the city again within ``REPEAT_CONTACT_STEPS`` is "lost" the same
way, map or no map (an agent that bumps, backs off and bumps again is not where its coasting
belief says). Numpy only: the map is a callable, e.g. ``env.unwrapped.city.free_mask``.

Where it was touched matters too (``info["collision_bearing"]``, a ring bumper's reading):
a robot touched ahead needs a wall ahead, so a wall beside or behind a belief no longer
explains the contact (:func:`contact_contradicts` asks the map at the touched point of
every pose within two standard deviations, :func:`contact_points`). The particle belief
weighs each particle by it (:func:`contact_log_likelihood`: MCL's bumper model) and is
"lost" as the EKF when the map has room at the touched point of most of its weight
(:func:`weigh_contact`).

What was touched matters (``info["collision_with"]``, :func:`contact_kinds`): movers are not
on the map, so only a contact with the city can contradict the belief; a contact with a
mover instead may have pushed and turned the robot beyond anything commanded
(:data:`PUSH_SPEED`, :data:`PUSH_TURN_RATE`; before kinds, every contact made a belief in
the open "lost" for 60 steps, and a robot turned by a vehicle kept its old heading).
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from typing import Any

import numpy as np

from localization.filtering.log_weights import log_sum_exp
from localization.geometry import Array, position_std, wrap_angle

__all__ = [
    "CONTACT_CLEARANCE",
    "CONTACT_GRID",
    "CONTACT_KINDS",
    "CONTACT_LOST_STEPS",
    "CONTACT_MISS",
    "CONTACT_MOTIONS",
    "CONTACT_SLACK",
    "CONTACT_WEIGHT",
    "PROJECTION_REACH",
    "PROJECTION_STEP",
    "PUSH_SPEED",
    "PUSH_TURN_RATE",
    "REPEAT_CONTACT_STEPS",
    "ROBOT_RADIUS",
    "Contact",
    "FreeSpace",
    "blocked_motion",
    "check_bearing",
    "check_free_space",
    "contact_contradicts",
    "contact_kinds",
    "contact_log_likelihood",
    "contact_points",
    "contact_projection",
    "free_at",
    "touched_points",
    "weigh_contact",
]

#: ``free_space(points (n, 2), margin) -> (n,) bool``: whether a disc of radius ``margin`` (m)
#: around each point is free of buildings (``City.free_mask``)
FreeSpace = Callable[[Array, float], Array]
#: m, the robot's radius: a disc covering its footprint, within which it is touched
#: (``envs.robot.ROBOT_RADIUS``, kept equal by a test: this module does not import the env)
ROBOT_RADIUS = 0.22
#: m of free space around the belief's mean (plus two position standard deviations) in which
#: a contact contradicts it: the robot's radius (:data:`ROBOT_RADIUS`) and 0.3 m of slack
CONTACT_CLEARANCE = ROBOT_RADIUS + 0.3
#: m of free space around a contact point (:func:`contact_points`) in which a contact with
#: a known bearing contradicts the belief: the robot is touched 0.13 m (the chassis' front
#: face) to 0.22 m (its rear corners) from its centre, so the obstacle lies within 0.09 m of
#: the point on :data:`ROBOT_RADIUS`
CONTACT_SLACK = 0.1
#: p(contact | pose) of a pose where the map has room (:func:`contact_log_likelihood`):
#: a contact with the city there is a bump sensor's false alarm or a map error
CONTACT_MISS = 0.05
#: share of a particle belief's weight that must sit where the map has room for a contact
#: to contradict it (:class:`~localization.filtering.particles.ParticleBelief`): the EKF's
#: two standard deviations
CONTACT_WEIGHT = 0.95
#: grid points per axis of :func:`contact_points` (over the 2-sigma ellipsoid of the pose)
CONTACT_GRID = 9
#: steps a contradicted belief stays "lost" (unless a restart replaces it first); then it drives
#: on (tuning cities 13-16, 600 episodes each: "lost" until a restart reached 80.5 % of the
#: kidnapped goals, 30 steps 85.5 %, 60 steps 86.0 %, with 3.3 / 4.4 / 3.8 contact steps per
#: kidnapped episode and 0.15 / 0.26 / 0.15 per nominal one)
CONTACT_LOST_STEPS = 60
#: steps within which a second contact with the city (after at least one step without one)
#: makes a belief that is not "tracking" "lost" as a contradicting contact does, map or no
#: map: an agent steering on a coasting belief that bumps, backs off and bumps again is not
#: where the belief says (tuning city 14, seed 3000093 kidnapped: a belief 2 m off, coasting
#: 250 steps through views off the maps, bumped a building 20 times, 10 steps apart; its two
#: standard deviations reached a wall, so no single contact contradicted it)
REPEAT_CONTACT_STEPS = 20
#: m, how far from the belief's mean :func:`contact_projection` looks for a position that
#: explains a contact, and the spacing of its grid
PROJECTION_REACH = 2.0
PROJECTION_STEP = 0.05
#: how :class:`~localization.filtering.belief.BeliefFilter` predicts a contact step
CONTACT_MOTIONS = ("blocked", "commanded")
#: what a contact can be with (``info["collision_with"]`` of ``AppearanceNav-v0``): the city
#: (buildings, the boundary: fixed, on the map) or traffic (moving vehicles, pedestrians)
CONTACT_KINDS = ("city", "traffic")
#: m/s a mover may push the robot in a contact step (one standard deviation): the fastest
#: mover's speed (``envs.traffic.VEHICLE_SPEED``)
PUSH_SPEED = 1.0
#: rad/s a mover may turn the robot in a contact step (one standard deviation): what the
#: fastest mover's step at the robot's rim can turn it, PUSH_SPEED / ROBOT_RADIUS (4.5 rad/s; on
#: held-out city 22 a vehicle's push turned a robot 2.2 rad in 0.7 s, stop 35). Two such steps make
#: the heading too uncertain to steer on ("lost"), until the images narrow it again.
#: Tuning cities 13-14, the scripted agent on the EKF belief among traffic, 200 episodes:
#: 1 rad/s 0.995 success, 2.54 contact steps per episode; 4.5 rad/s 0.99, 1.49
PUSH_TURN_RATE = PUSH_SPEED / ROBOT_RADIUS
#: a step's contact: False (none), True (something fixed: a contact of unknown kind), or the
#: kinds touched (``info["collision_with"]``, a collection of ``CONTACT_KINDS``)
Contact = bool | Collection[str]


def contact_kinds(contact: object, name: str = "contact") -> frozenset[str]:
    """The kinds of a step's ``contact`` (:data:`Contact`): True is ``{"city"}`` (a bump into
    something fixed, what a plain bumper flag meant before kinds), False nothing.

    Raises
    ------
    TypeError
        If ``contact`` (the argument ``name``) is neither a bool nor a collection.
    ValueError
        If it holds a kind not in :data:`CONTACT_KINDS`.
    """
    if isinstance(contact, (bool, np.bool_)):
        return frozenset({"city"}) if contact else frozenset()
    if isinstance(contact, str) or not isinstance(contact, Collection):
        raise TypeError(f"{name} must be a bool or a collection of {CONTACT_KINDS} "
                         f"(info['collision_with']), got {contact!r}")
    bad = [k for k in contact if k not in CONTACT_KINDS]
    if bad:
        raise ValueError(f"{name}: unknown contact kinds {bad}; choose from {CONTACT_KINDS}")
    return frozenset(contact)


def blocked_motion(motion_model: Any, x: Array, u: Array, pushed: bool = False
                   ) -> tuple[Array, Array]:
    """The control of a contact step and the covariance added to its prediction.

    The robot is taken as blocked: ``u_blocked = [0, w]`` (no translation, the commanded
    turn). What the commanded control would have added, the translation
    ``d = |F(x, u) - F(x, u_blocked)|`` and the turn ``a = |w| dt``, becomes one standard
    deviation: ``Q_contact = diag(d^2, d^2, a^2)`` (isotropic in x, y: a push can go
    sideways). A contact with a mover (``pushed``) may also have moved the robot by the
    mover's step and turned it: ``Q_contact += diag(s^2, s^2, b^2)`` with
    ``s = PUSH_SPEED dt``, ``b = PUSH_TURN_RATE dt`` (``dt`` of ``motion_model``).

    Returns
    -------
    u_blocked : ndarray (2,)
    Q_contact : ndarray (3, 3)
    """
    u = np.asarray(u, dtype=np.float64)
    u_blocked = np.array([0.0, u[1]])
    moved, stayed = motion_model.predict(x, u), motion_model.predict(x, u_blocked)
    d = float(np.hypot(*(moved[:2] - stayed[:2])))
    a = float(abs(wrap_angle(stayed[2] - x[2])))
    Q = np.diag([d * d, d * d, a * a])
    if pushed:
        dt = float(motion_model.dt)
        Q += np.diag([(PUSH_SPEED * dt) ** 2] * 2 + [(PUSH_TURN_RATE * dt) ** 2])
    return u_blocked, Q


def check_free_space(free_space: object) -> FreeSpace | None:
    """``free_space`` itself if callable or None; else a TypeError naming it."""
    if free_space is not None and not callable(free_space):
        raise TypeError("free_space must be None or a callable free_space(points (n, 2), "
                        f"margin) -> (n,) bool (e.g. city.free_mask), got "
                        f"{type(free_space).__name__}")
    return free_space


def contact_contradicts(free_space: FreeSpace, x: Array, P: Array,
                        bearing: float | None = None) -> bool:
    """Whether a contact contradicts the belief ``x`` (3,), ``P`` (3, 3).

    Without a ``bearing``: the map is free for ``CONTACT_CLEARANCE`` plus two position
    standard deviations all around the belief's mean. With the ``bearing`` (rad, from the
    heading) of where the robot was touched (``info["collision_bearing"]``): the map is free
    for ``CONTACT_SLACK`` (plus the points' spacing) at the contact point
    (:func:`contact_points`) of every pose within two standard deviations of the belief:
    a wall beside or behind a belief that was touched ahead does not explain the contact.
    A heading too uncertain for the bearing to say a side (2 sigma >= pi) falls back to
    the rule without one."""
    if bearing is None or not np.isfinite(bearing) or 4.0 * P[2, 2] >= np.pi ** 2:
        sigma = position_std(P)
        return bool(np.all(free_at(free_space, np.asarray(x[None, :2], dtype=np.float64),
                                 CONTACT_CLEARANCE + 2.0 * sigma)))
    points, spacing = contact_points(x, P, float(bearing))
    return bool(np.all(free_at(free_space, points, CONTACT_SLACK + spacing)))


def contact_projection(free_space: FreeSpace, x: Array, P: Array, bearing: float,
                       reach: float = PROJECTION_REACH, step: float = PROJECTION_STEP
                       ) -> Array | None:
    """The pose nearest the belief ``x`` (3,), ``P`` (3, 3) at which the map explains a
    contact touched at ``bearing`` (rad from the heading): the estimate projection of
    constrained Kalman filtering (Simon & Chia 2002), the bumper's reading as a constraint.

    Candidates are the belief's heading at positions ``x[:2] + d`` on a grid (``step`` m)
    within ``reach`` m; a candidate explains the contact when a building lies within
    ``CONTACT_SLACK`` of its touched point (:func:`touched_points`) while its centre is
    free for ``ROBOT_RADIUS - CONTACT_SLACK`` (the robot touched, not inside a wall). Of
    those, the one nearest in ``d^T P_xy^-1 d`` (Mahalanobis in position) is returned; None
    when none lies within ``reach``. A belief shoved sideways off the robot's true path
    thus moves to the wall it touched, instead of coasting parallel to it. (The particle
    belief instead moves a share of its particles along the touched direction,
    :mod:`~localization.filtering.contact_spread`: many poses, the images choose.)

    Returns
    -------
    pose : ndarray (3,) or None
    """
    t = np.arange(-reach, reach + 0.5 * step, step)
    d = np.stack(np.meshgrid(t, t), -1).reshape(-1, 2)
    d = d[np.einsum("ij,ij->i", d, d) <= reach * reach]
    X = np.column_stack([x[0] + d[:, 0], x[1] + d[:, 1], np.full(len(d), x[2])])
    ok = (~free_at(free_space, touched_points(X, bearing), CONTACT_SLACK)
          & free_at(free_space, X[:, :2], ROBOT_RADIUS - CONTACT_SLACK))
    if not ok.any():
        return None
    d = d[ok]
    inverse = np.linalg.inv(P[:2, :2] + 1e-12 * np.eye(2))
    return X[ok][int(np.argmin(np.einsum("ij,jk,ik->i", d, inverse, d)))]


def contact_log_likelihood(free_space: FreeSpace, X: Array, bearing: float | None = None
                           ) -> Array:
    """log p(contact | pose) for particles ``X`` (N, 3): 0 where the map explains a contact
    with the city (a building within ``CONTACT_SLACK`` of the touched point at ``bearing``,
    or without a bearing within ``CONTACT_CLEARANCE`` of the position), ``log
    CONTACT_MISS`` where it has room (MCL's bumper model: a particle in the open that feels
    a bump is unlikely, not impossible)."""
    return np.where(_explained(free_space, X, bearing), 0.0, np.log(CONTACT_MISS))


def weigh_contact(free_space: FreeSpace, X: Array, log_weights: Array,
                  bearing: float | None = None) -> tuple[Array, bool]:
    """A contact with the city against particles ``X`` (N, 3) of ``log_weights`` (N,):
    its :func:`contact_log_likelihood` (N,), and whether it contradicts the belief (more
    than ``CONTACT_WEIGHT`` of the weight where the map has room)."""
    explained = _explained(free_space, X, bearing)
    share = float(np.exp(log_sum_exp(log_weights[explained]))) if explained.any() else 0.0
    return np.where(explained, 0.0, np.log(CONTACT_MISS)), share < 1.0 - CONTACT_WEIGHT


def _explained(free_space: FreeSpace, X: Array, bearing: float | None) -> Array:
    """(N,) bool: whether the map explains a contact with the city at each pose of ``X``
    (:func:`contact_log_likelihood`)."""
    X = np.asarray(X, dtype=np.float64)
    if bearing is None or not np.isfinite(bearing):
        return ~free_at(free_space, X[:, :2], CONTACT_CLEARANCE)
    return ~free_at(free_space, touched_points(X, bearing), CONTACT_SLACK)


def touched_points(X: Array, bearing: float) -> Array:
    """Where robots at poses ``X`` (n, 3) are touched at ``bearing`` (rad from the
    heading): ``p + ROBOT_RADIUS [cos(th + bearing), sin(th + bearing)]`` (n, 2)."""
    angle = X[:, 2] + bearing
    return X[:, :2] + ROBOT_RADIUS * np.stack([np.cos(angle), np.sin(angle)], -1)


def contact_points(x: Array, P: Array, bearing: float, n: int = CONTACT_GRID
                   ) -> tuple[Array, float]:
    """Where a robot at a pose within two standard deviations of the belief ``x`` (3,),
    ``P`` (3, 3) would have been touched at ``bearing``: ``p + ROBOT_RADIUS [cos(th +
    bearing), sin(th + bearing)]`` for the poses ``(p, th) = x + 2 L s`` (``P = L L^T``) of
    an ``n``-per-axis grid of ``s`` in the unit ball.

    Returns
    -------
    points : ndarray (k, 2)
    spacing : float
        m within which every contact point of the 2-sigma ellipsoid lies from one of
        ``points`` (half a grid cell's diagonal: what a map query's margin adds).
    """
    L = np.linalg.cholesky(P + 1e-12 * np.eye(3))
    t = np.linspace(-1.0, 1.0, n)
    grid = np.stack(np.meshgrid(t, t, t), -1).reshape(-1, 3)
    grid = grid[np.einsum("ij,ij->i", grid, grid) <= 1.0 + 1e-9]
    points = touched_points(x + 2.0 * grid @ L.T, bearing)
    reach = position_std(P) + ROBOT_RADIUS * float(np.sqrt(max(P[2, 2], 0.0)))
    return points, float(np.sqrt(3.0) / 2.0 * 4.0 / (n - 1) * reach)


def check_bearing(bearing: object, name: str = "bearing") -> float | None:
    """``bearing`` as a float (NaN: no bearing, as None); else a TypeError naming it."""
    if bearing is None:
        return None
    if isinstance(bearing, (bool, np.bool_)) or not isinstance(bearing, (int, float, np.number)):
        raise TypeError(f"{name} must be None or a float in rad (info['collision_bearing']), "
                        f"got {bearing!r}")
    return float(bearing) if np.isfinite(bearing) else None


def free_at(free_space: FreeSpace, points: Array, margin: float) -> Array:
    """``free_space(points, margin)``, checked to return one bool per point."""
    free = np.asarray(free_space(points, margin), dtype=bool)
    if free.shape != (len(points),):
        raise ValueError(f"free_space must return one bool per point, got shape {free.shape}")
    return free
