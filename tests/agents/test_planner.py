"""Street planner: shortest street paths, projections, progress along a plan."""

import numpy as np
import pytest

from agents.planner import PlannedPath, StreetPlanner, path_length, project_to_segments
from envs.scene import generate_city


@pytest.fixture(scope="module")
def city():
    return generate_city(0)


def _on_street(city, points, tol=1e-9):
    c = city.street_centers
    near = lambda v: np.min(np.abs(v[:, None] - c[None]), axis=1) <= tol
    return near(points[:, 0]) | near(points[:, 1])


def test_project_to_segments():
    a = np.array([[0.0, 0.0], [0.0, 0.0]])
    b = np.array([[2.0, 0.0], [0.0, 2.0]])
    t, foot, d = project_to_segments(np.array([1.0, 1.0]), a, b)
    np.testing.assert_allclose(t, [0.5, 0.5])
    np.testing.assert_allclose(foot, [[1, 0], [0, 1]])
    np.testing.assert_allclose(d, [1, 1])
    t, _, d = project_to_segments(np.array([3.0, 0.0]), a, b)
    assert t[0] == 1.0 and d[0] == 1.0


def test_plan_is_shortest_manhattan_path_on_streets(city):
    planner = StreetPlanner(city)
    c = city.street_centers
    start, goal = np.array([c[0], c[0]]), np.array([c[-1], c[-1]])
    path = planner.plan(start, goal)
    np.testing.assert_allclose(path[0], start)
    np.testing.assert_allclose(path[-1], goal)
    assert _on_street(city, path).all()
    assert path_length(path) == pytest.approx(2 * (c[-1] - c[0]))  # Manhattan distance
    # every leg runs along one street (axis-aligned)
    assert np.all(np.min(np.abs(np.diff(path, axis=0)), axis=1) < 1e-9)


def test_plan_between_points_off_the_nodes(city):
    planner = StreetPlanner(city)
    rng = np.random.default_rng(0)
    for _ in range(20):
        s, g = city.random_street_point(rng), city.random_street_point(rng)
        path = planner.plan(s, g)
        assert _on_street(city, path).all()
        # the street distance is at least the Manhattan distance and at most a detour of two blocks
        manhattan = np.abs(s - g).sum()
        assert manhattan - 1e-9 <= path_length(path) <= manhattan + 4 * (city.street_centers[1] - city.street_centers[0])
        assert city.free_mask(np.linspace(path[:-1], path[1:], 20).reshape(-1, 2), 0.3).all()


def test_same_segment_is_direct(city):
    planner = StreetPlanner(city)
    c = city.street_centers
    s, g = np.array([c[0] + 0.5, c[1]]), np.array([c[0] + 3.0, c[1]])
    np.testing.assert_allclose(planner.plan(s, g), [s, g])


def test_start_off_the_street_joins_its_nearest_street(city):
    planner = StreetPlanner(city)
    c = city.street_centers
    start = np.array([c[0] + 0.6, c[1] + 2.5])  # on the street's side, not on the centreline
    path = planner.plan(start, np.array([c[-1], c[-1]]))
    np.testing.assert_allclose(path[0], start)
    np.testing.assert_allclose(path[1], [c[0], c[1] + 2.5])


def test_bad_points_raise(city):
    planner = StreetPlanner(city)
    with pytest.raises(ValueError, match="finite"):
        planner.plan([np.nan, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match=r"start must have shape \(2,\)"):
        planner.plan([0.0], [0.0, 0.0])


def test_planned_path_progress():
    path = PlannedPath([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]], step=0.1)
    assert path.remaining() == pytest.approx(4.0)
    path.update(np.array([1.0, 0.2]))
    assert path.remaining() == pytest.approx(3.0)
    np.testing.assert_allclose(path.ahead(1.5), [2.0, 0.5])
    np.testing.assert_allclose(path.ahead(100.0), [2.0, 2.0])
    assert path.distance_to(np.array([1.0, 0.2])) == pytest.approx(0.2)
    path.update(np.array([0.0, 0.0]))  # progress never goes back
    assert path.remaining() == pytest.approx(3.0)
    with pytest.raises(ValueError, match="shape"):
        PlannedPath(np.zeros((3, 3)))


def _headings(path):
    d = np.diff(path, axis=0)
    return np.arctan2(d[:, 1], d[:, 0])


def test_drive_is_smooth_and_stays_on_the_streets(city):
    planner = StreetPlanner(city, turn_radius=0.8)
    rng = np.random.default_rng(3)
    for _ in range(20):
        start = city.random_street_point(rng)
        pose = np.array([*start, rng.uniform(-np.pi, np.pi)])
        goal = city.random_street_point(rng)
        path = planner.drive(pose, goal)
        np.testing.assert_allclose(path[0], pose[:2])
        np.testing.assert_allclose(path[-1], goal)
        fine = PlannedPath(path, step=0.05).points
        assert city.free_mask(fine, 0.3).all()
        # after the start the heading never reverses: corners are arcs, no U-turn on a street
        turns = np.abs(np.angle(np.exp(1j * np.diff(_headings(fine[2:])))))
        assert turns.max() < np.pi / 2
        # and away from the start, a corner is a quarter circle of the full radius
        late = fine[len(fine) // 2:]
        assert np.abs(np.angle(np.exp(1j * np.diff(_headings(late))))).max() < 0.2  # a sharp corner: pi/2


def test_drive_sets_off_along_its_heading_unless_turning_round_saves_a_lot(city):
    planner = StreetPlanner(city, u_turn_cost=4.0)
    c = city.street_centers
    y = c[1]
    # on a street, facing +x; the goal 3 m behind: turning round (3 m + 4) beats a block loop
    pose = np.array([c[1] + 2.0, y, 0.0])
    back = planner.drive(pose, [c[1] + -1.0 + 0.5, y])
    assert path_length(back) == pytest.approx(2.5)
    # the goal ahead on the same street: straight there
    ahead = planner.drive(pose, [c[1] + 3.5, y])
    assert path_length(ahead) == pytest.approx(1.5)
    assert np.all(np.diff(ahead[:, 0]) > 0)
    # with turning round made expensive, it drives round the block instead
    looping = StreetPlanner(city, u_turn_cost=100.0).drive(pose, [c[1] + -1.0 + 0.5, y])
    assert path_length(looping) > 10.0
    with pytest.raises(ValueError, match="pose"):
        planner.drive([0.0, 0.0], [1.0, 1.0])


def test_a_belief_that_coasted_off_the_map_is_planned_from_the_city_edge(city):
    """A kidnapped EKF coasted 12.8 m past the boundary of the 20 m city: the navigator
    plans from the nearest point of the city instead of stopping the episode; a pose in
    other units and a goal outside the city are still refused."""
    from agents.scripted import Navigator

    goal = np.array([3.0, 1.0])
    off, edge = np.array([22.8, -4.6, 0.3]), np.array([city.bounds[1], -4.6, 0.3])
    path = Navigator(city).update(off, goal)
    np.testing.assert_array_equal(path.points, Navigator(city).update(edge, goal).points)
    with pytest.raises(ValueError, match="far outside the city"):
        Navigator(city).update(1000.0 * off, goal)  # millimetres
    with pytest.raises(ValueError, match="far outside the city"):
        Navigator(city).update(edge, off[:2])
