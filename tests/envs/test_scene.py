"""The generated city: determinism, free space, street graph, route, MJCF."""

import envs  # noqa: F401  (first: chooses MUJOCO_GL before mujoco is imported)

# isort: split
import mujoco
import numpy as np
import pytest

from envs.scene import generate_city


def test_same_seed_same_city_different_seed_different_city():
    a, b, c = generate_city(3), generate_city(3), generate_city(4)
    assert a.buildings == b.buildings
    assert a.buildings != c.buildings
    assert a.to_mjcf() == b.to_mjcf() != c.to_mjcf()


def test_layout_and_free_space():
    city = generate_city(0)
    assert city.size == 20.0 and np.allclose(city.street_centers, [-9, -3, 3, 9])
    assert 8 <= len(city.buildings) <= 40
    assert any(b.landmark for b in city.buildings)
    for b in city.buildings:
        assert not city.is_free(b.center[0], b.center[1])
    assert city.is_free(-9.0, -9.0, 0.3)  # a corner of the outer ring street
    assert not city.is_free(10.5, 0.0) and not city.is_free(np.nan, 0.0)
    pts = np.random.default_rng(0).uniform(-11, 11, (500, 2))
    assert np.array_equal(city.free_mask(pts, 0.2), [city.is_free(x, y, 0.2) for x, y in pts])
    rng = np.random.default_rng(1)
    for _ in range(50):
        x, y, yaw = city.random_free_pose(rng, margin=0.3)
        assert city.is_free(x, y, 0.3) and -np.pi <= yaw <= np.pi


def test_configurable_size():
    city = generate_city(0, city_size=32.5, block_size=5.0, street_width=2.5)
    assert len(city.street_centers) == 5
    assert city.street_centers[0] == pytest.approx(-16.25 + 1.25)
    with pytest.raises(ValueError, match="too small"):
        generate_city(0, city_size=3.0)


def test_street_graph_and_route_stay_on_streets():
    city = generate_city(0)
    nodes, edges = city.street_graph()
    assert nodes.shape == (16, 2) and len(edges) == 24
    for a, b in edges:
        assert np.isclose(np.abs(nodes[a] - nodes[b]).sum(), np.abs(nodes[a] - nodes[b]).max())  # axis-aligned
        for t in np.linspace(0, 1, 21):
            assert city.is_free(*((1 - t) * nodes[a] + t * nodes[b]), margin=0.3)
    route = city.route()
    assert len(route) == 16 and len({tuple(p) for p in route}) == 16  # visits every intersection once
    steps = np.diff(np.vstack([route, route[:1]]), axis=0)
    assert np.all(np.count_nonzero(steps, axis=1) == 1)  # consecutive waypoints share a street
    odd = generate_city(0, city_size=26.0).route()  # 5 streets: outer ring
    assert len(odd) == 16


def test_mjcf_compiles():
    model = mujoco.MjModel.from_xml_string(generate_city(0).to_mjcf())
    assert model.ngeom < 80
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_clearance_agrees_with_free_mask():
    city = generate_city(0)
    rng = np.random.default_rng(0)
    points = rng.uniform(-city.half - 1, city.half + 1, size=(4000, 2))
    c = city.clearance(points)
    for margin in (0.0, 0.22, 0.5):
        free = city.free_mask(points, margin)
        assert np.all(c[free] >= margin - 1e-12)
        # free_mask grows each building by a square of margin: its corners reach margin * sqrt 2
        assert np.all(free[c > margin * np.sqrt(2) + 1e-9])
    x0, y0, x1, y1 = city.footprints()[0]
    inside = np.array([[0.5 * (x0 + x1), 0.5 * (y0 + y1)]])
    assert city.clearance(inside)[0] == pytest.approx(-0.5 * min(x1 - x0, y1 - y0))
