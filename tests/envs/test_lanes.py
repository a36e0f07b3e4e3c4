"""Driving lanes of the street graph and the poses sampled around them."""

import itertools

import numpy as np
import pytest

from envs.lanes import lane_poses, street_lanes, street_tour
from envs.motion_model import wrap_angle
from envs.scene import generate_city


@pytest.fixture(scope="module")
def city():
    return generate_city(0)


def test_route_lanes_follow_the_loop(city):
    lanes = street_lanes(city, "route")
    wp = city.route()
    segments = [lane for lane in lanes if lane.turn == 0]
    assert len(segments) == len(wp)
    for lane in lanes:  # consecutive poses along a lane are continuous, headings agree
        p = np.array([lane.pose(t) for t in np.linspace(0, 1, 21)])
        step = np.hypot(*np.diff(p[:, :2], axis=0).T)
        assert np.allclose(step, lane.length / 20, rtol=1e-3)  # chords of an arc
        assert np.allclose(lane.pose(1.0)[:2], lane.end, atol=1e-9)
        heading = np.arctan2(*np.diff(p[:, :2], axis=0).T[::-1])
        assert np.allclose(wrap_angle(heading - p[:-1, 2]), 0, atol=np.pi / 20 + 1e-9)
    turns = [lane for lane in lanes if lane.turn != 0]
    assert turns and all(abs(lane.curvature) == pytest.approx(1 / 0.8) for lane in turns)
    for lane in turns:  # an arc ends turned by +-90 degrees
        assert wrap_angle(lane.pose(1.0)[2] - lane.yaw0) == pytest.approx(lane.turn * np.pi / 2)


def test_street_lanes_cover_both_directions(city):
    lanes = street_lanes(city, "streets")
    nodes, edges = city.street_graph()
    assert sum(lane.turn == 0 for lane in lanes) == 2 * len(edges)
    # each interior node has 4 streets: 4 x 2 turns; corners 2, borders 4 (in: 3 x out: 2)
    assert sum(lane.turn != 0 for lane in lanes) > len(nodes) * 2


def test_lane_poses_stay_near_lanes_and_are_free(city):
    rng = np.random.default_rng(0)
    poses, curvature = lane_poses(city, 500, rng, lanes="route", lateral=0.25, heading=0.1)
    assert poses.shape == (500, 3) and curvature.shape == (500,)
    assert city.free_mask(poses[:, :2], 0.32).all()
    assert np.all(np.abs(poses[:, 2]) <= np.pi)
    street = np.abs(poses[:, :2, None] - city.street_centers[None, None]).min(axis=2)
    assert np.all(street.min(axis=1) < 1.0)  # on a street
    assert 0.05 < np.mean(curvature != 0) < 0.8  # turns are sampled, weighted up
    again, _ = lane_poses(city, 500, np.random.default_rng(0), lanes="route", lateral=0.25,
                          heading=0.1)
    assert np.array_equal(poses, again)


def test_bad_lane_options(city):
    with pytest.raises(ValueError, match="lanes"):
        street_lanes(city, "highway")
    with pytest.raises(ValueError, match="turn_radius"):
        street_lanes(city, "route", turn_radius=0.0)
    with pytest.raises(ValueError, match="lateral"):
        lane_poses(city, 10, np.random.default_rng(0), lateral=-1.0)
    with pytest.raises(RuntimeError, match="free"):
        lane_poses(city, 10, np.random.default_rng(0), margin=5.0)


def test_street_tour_drives_the_graph_without_u_turns(city):
    nodes, edges = city.street_graph()
    linked = {tuple(sorted(e)) for e in edges}
    tour = street_tour(city, 200.0, np.random.default_rng(3))
    index = [int(np.flatnonzero(np.all(nodes == p, axis=1))[0]) for p in tour]
    assert all(tuple(sorted(ab)) in linked for ab in itertools.pairwise(index))  # along streets
    assert all(a != c for a, c in zip(index, index[2:]))  # never straight back
    length = np.hypot(*np.diff(tour, axis=0).T).sum()
    assert 200.0 <= length < 200.0 + city.size
    driven = {tuple(ab) for ab in itertools.pairwise(index)}
    assert any((b, a) in driven for a, b in driven)  # streets are driven both ways
    assert len({tuple(sorted(ab)) for ab in driven}) > len(edges) / 2
    assert np.array_equal(tour, street_tour(city, 200.0, np.random.default_rng(3)))
    with pytest.raises(ValueError, match="length"):
        street_tour(city, 0.0, np.random.default_rng(0))
