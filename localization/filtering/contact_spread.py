"""Moving a contradicted particle belief to the walls the robot could have touched.

A contact with the city where the map has room at the touched point of almost every
particle (:func:`~localization.filtering.map_contact.weigh_contact` says it contradicts the
belief) weighs every particle alike, so the contact likelihood moves nothing: a belief 1.5 m
off the wall the robot is pressed against stays there, and where the images are off the
localizer's maps nothing else moves it either (held-out city 21, reset seed 3000073: the
scripted agent drove into the same wall seven times, docs/benchmarks.md §11).

Monte Carlo localization's answer to data the particles cannot explain is to put particles
where the data fit (Augmented MCL injects them where the images point). A contact says where
the robot is relative to the map: a wall at its touched point. With the names of the code,
the particles are resampled and a share ``spread`` of them is replaced by copies of
weight-drawn particles, each turned by ``e ~ N(0, heading_noise^2)`` and moved along the
direction it was touched from, ``u = [cos(yaw + e + bearing), sin(yaw + e + bearing)]`` (a
uniform direction when the bearing is unknown), to the first point ``p + t u``, ``t = 0, step, ..., max_distance``,
where the map has a building within ``CONTACT_SLACK`` of the touched point
``p + t u + ROBOT_RADIUS u`` (a ray cast on the map). Copies that meet no wall within
``max_distance`` keep their pose. The contact likelihood then weighs the set: the moved
copies explain the contact, the rest do not (``CONTACT_MISS``), and the images decide
among the walls. Numpy only; the map is the callable of :mod:`~.map_contact`.
"""

from __future__ import annotations

import numpy as np

from localization._validation import check_real
from localization.filtering.map_contact import CONTACT_SLACK, ROBOT_RADIUS, FreeSpace
from localization.geometry import Array, wrap_angle

__all__ = ["SPREAD_STEP", "ContactSpread", "cast_to_walls"]

#: m between the points a ray visits (half the robot's chassis clearance of a wall)
SPREAD_STEP = 0.05


def cast_to_walls(free_space: FreeSpace, X: Array, bearing: float | None,
                  rng: np.random.Generator, max_distance: float, heading_noise: float,
                  step: float = SPREAD_STEP) -> tuple[Array, Array]:
    """Poses ``X`` (n, 3) turned by a heading draw and moved along the touched direction to
    the first wall within ``max_distance`` (see the module docstring).

    Returns
    -------
    moved : ndarray (n, 3)
        The moved poses (the turned pose where no wall was met).
    hit : ndarray (n,) bool
        Whether a wall was met.
    """
    X = np.array(X, dtype=np.float64)
    X[:, 2] = wrap_angle(X[:, 2] + rng.normal(0.0, heading_noise, len(X)))
    if bearing is None or not np.isfinite(bearing):
        angle = rng.uniform(-np.pi, np.pi, len(X))
    else:
        angle = X[:, 2] + bearing
    u = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (n, 2)
    t = np.arange(0.0, max_distance + 0.5 * step, step)  # (k,)
    touched = X[:, None, :2] + (t[None, :, None] + ROBOT_RADIUS) * u[:, None, :]  # (n, k, 2)
    wall = ~np.asarray(free_space(touched.reshape(-1, 2), CONTACT_SLACK), dtype=bool)
    wall = wall.reshape(len(X), len(t))
    hit = wall.any(axis=1)
    first = np.argmax(wall, axis=1)
    X[hit, :2] += t[first[hit], None] * u[hit]
    return X, hit


class ContactSpread:
    """How a particle belief answers a contact that contradicts it (module docstring).

    Parameters
    ----------
    spread : float in [0, 1]
        Share of the particles moved to walls (0: none; the belief only says "lost").
    max_distance : float
        m a particle may be moved along its ray.
    heading_noise : float
        Standard deviation (rad) of the heading draw of each moved particle.
    """

    def __init__(self, spread: float = 0.5, max_distance: float = 2.0,
                 heading_noise: float = 0.2) -> None:
        self.spread = check_real(spread, "contact_spread", low=0.0, high=1.0)
        self.max_distance = check_real(max_distance, "contact_spread_distance", low=0.0,
                                       low_open=True)
        self.heading_noise = check_real(heading_noise, "heading_noise", low=0.0)

    def size(self, n: int, rng: np.random.Generator) -> int:
        """How many of ``n`` particles to move: Binomial(n, spread)."""
        return int(rng.binomial(n, self.spread)) if self.spread > 0 else 0

    def draw(self, free_space: FreeSpace, X: Array, weights: Array, bearing: float | None,
             rng: np.random.Generator, n: int) -> Array:
        """``n`` poses (n, 3): copies of particles of ``X`` (N, 3) drawn by their
        ``weights`` (N,), moved to the walls (:func:`cast_to_walls`)."""
        parents = rng.choice(len(X), size=n, p=weights / weights.sum())
        return cast_to_walls(free_space, X[parents], bearing, rng, self.max_distance,
                             self.heading_noise)[0]
