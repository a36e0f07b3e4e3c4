"""A contact that contradicts the particle belief moves a share of it to the walls it could
have come from (localization.filtering.contact_spread)."""

from __future__ import annotations

import numpy as np
import pytest

from envs.motion_model import UnicycleModel
from localization.filtering.contact_spread import SPREAD_STEP, ContactSpread, cast_to_walls
from localization.filtering.map_contact import CONTACT_SLACK, ROBOT_RADIUS, contact_log_likelihood
from localization.filtering.particles import ParticleBelief


class Wall:
    """A free_space with a building at x > ``edge``."""

    def __init__(self, edge: float) -> None:
        self.edge = edge

    def __call__(self, points: np.ndarray, margin: float) -> np.ndarray:
        return points[:, 0] < self.edge - margin


def test_a_ray_stops_at_the_first_point_whose_touched_rim_meets_the_wall() -> None:
    X = np.array([[3.0, 0.0, 0.0], [3.0, 1.0, np.pi / 2], [4.8, 0.0, 0.0]])
    moved, hit = cast_to_walls(Wall(5.0), X, 0.0, np.random.default_rng(0), 2.0, 0.0)
    # ahead: the rim x + t + ROBOT_RADIUS within CONTACT_SLACK of x = 5 first at t = 1.70
    t = np.ceil((5.0 - CONTACT_SLACK - ROBOT_RADIUS - 3.0) / SPREAD_STEP - 1e-9) * SPREAD_STEP
    np.testing.assert_allclose(moved[0], [3.0 + t, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(moved[1], X[1])  # facing north along the wall: no wall met
    np.testing.assert_allclose(moved[2], X[2])  # already touching: not moved
    assert hit.tolist() == [True, False, True]


@pytest.mark.parametrize("bearing", [0.0, 1.2, -2.0, None])
def test_moved_particles_explain_the_contact(bearing: float | None) -> None:
    rng = np.random.default_rng(1)
    X = np.column_stack([rng.uniform(2.5, 4.5, 400), rng.uniform(-1, 1, 400),
                         rng.uniform(-np.pi, np.pi, 400)])
    moved, hit = cast_to_walls(Wall(5.0), X, bearing, rng, 3.0, 0.3)
    assert hit.sum() > 40
    np.testing.assert_array_equal(contact_log_likelihood(Wall(5.0), moved[hit], bearing), 0.0)
    assert np.all(np.hypot(*(moved[:, :2] - X[:, :2]).T) <= 3.0 + 1e-9)


def test_the_spread_draws_a_binomial_share_and_names_bad_settings() -> None:
    rng = np.random.default_rng(2)
    sizes = [ContactSpread(0.5).size(1000, rng) for _ in range(200)]
    assert 480 < np.mean(sizes) < 520
    assert ContactSpread(0.0).size(1000, rng) == 0
    with pytest.raises(ValueError, match="contact_spread"):
        ContactSpread(1.5)
    with pytest.raises(ValueError, match="contact_spread_distance"):
        ContactSpread(0.5, max_distance=0.0)


def _cloud_facing_a_wall(localizer, features, **options) -> ParticleBelief:
    """500 particles around (3, 0) facing east, 2 m from a wall at x = 5 (the rim 1.78 m
    short of it): a bump ahead contradicts them."""
    W, poses, _ = features
    pf = ParticleBelief(localizer, UnicycleModel(0.1), n_particles=500, seed=0,
                        free_space=Wall(5.0), **options)
    pf.reset(W[0], x0=poses[0])
    rng = np.random.default_rng(3)
    pf._set(np.column_stack([3.0 + rng.normal(0, 0.1, (500, 2)), rng.normal(0, 0.05, 500)]))
    return pf


@pytest.mark.parametrize("track_mode", [False, True])
def test_a_contradicting_bump_moves_the_belief_to_the_wall(localizer, features, track_mode):
    """The contact alone (the images far from this place weigh every particle alike) takes
    the reported pose to the wall; without the spread it stays 1.7 m short, "lost" either way."""
    W = features[0]
    spread = _cloud_facing_a_wall(localizer, features, track_mode=track_mode)
    spread.step(np.zeros(2), W[1], contact=("city",), bearing=0.0)
    assert spread.status == "lost"
    if track_mode:  # the tracker's EKF is condemned: the next report follows the particles
        spread.step(np.zeros(2), W[1])
    assert spread.pose_mean[0] > 4.5
    still = _cloud_facing_a_wall(localizer, features, track_mode=track_mode, contact_spread=0.0)
    still.step(np.zeros(2), W[1], contact=("city",), bearing=0.0)
    assert still.status == "lost" and still.pose_mean[0] < 3.3


def test_a_bump_the_belief_explains_moves_nothing(localizer, features):
    W = features[0]
    pf = _cloud_facing_a_wall(localizer, features, track_mode=False)
    pf._set(pf.particles + [1.7, 0.0, 0.0])  # at the wall now
    before = pf.particles.copy()
    pf.step(np.zeros(2), W[1], contact=("city",), bearing=0.0)
    assert pf.status != "lost"
    assert abs(pf.pose_mean[0] - before[:, 0].mean()) < 0.1
