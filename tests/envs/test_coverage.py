"""The coverage sampler (envs.coverage), the "coverage" dataset mode and off-lane drives."""

import numpy as np
import pytest

from envs import AppearanceNavEnv, collect_dataset
from envs.coverage import corner_mask, coverage_poses, street_mask
from envs.datasets import POSE_MARGIN, drive_off_lane
from envs.off_lane import OffLanePilot, off_lane_waypoints
from envs.scene import generate_city


@pytest.fixture(scope="module")
def city():
    return generate_city(17)


@pytest.fixture(scope="module")
def env():
    e = AppearanceNavEnv(scene_seed=0, image_size=(32, 32))
    yield e
    e.close()


def street_cells(city, xy):
    """Index of the intersection square (k*k of them) or street segment (after them) each
    point is in; -1 elsewhere."""
    c, hw, k = city.street_centers, 0.5 * city.street_width, len(city.street_centers)
    d = np.abs(xy[:, :, None] - c[None, None, :])  # (n, 2, k)
    near, nearest = d.min(axis=2) <= hw, d.argmin(axis=2)
    block = np.searchsorted(c, xy) - 1  # the gap between streets (0 .. k-2) along x and y
    cell = np.full(len(xy), -1)
    both = near[:, 0] & near[:, 1]
    cell[both] = nearest[both, 1] * k + nearest[both, 0]
    for axis in (0, 1):  # on a street along `axis`: near the other coordinate's centreline
        only = near[:, 1 - axis] & ~near[:, axis]
        cell[only] = k * k + axis * k * (k - 1) + nearest[only, 1 - axis] * (k - 1) \
            + block[only, axis]
    return cell, k * k + 2 * k * (k - 1)


def test_poses_are_on_free_street_surface(city):
    poses = coverage_poses(city, 3000, np.random.default_rng(0))
    assert poses.shape == (3000, 3) and poses.dtype == np.float64
    assert np.all(city.free_mask(poses[:, :2], 0.32))  # clear of buildings and the border
    c, hw = city.street_centers, 0.5 * city.street_width
    on_asphalt = [np.min(np.abs(poses[:, k, None] - c), axis=1) <= hw for k in (0, 1)]
    assert np.all(on_asphalt[0] | on_asphalt[1])
    assert np.all((poses[:, 2] >= -np.pi) & (poses[:, 2] < np.pi))


def test_every_heading_and_every_street_cell_is_covered(city):
    poses = coverage_poses(city, 3000, np.random.default_rng(1))
    counts = np.bincount(((poses[:, 2] + np.pi) // (np.pi / 4)).astype(int), minlength=8)
    assert counts.shape == (8,) and counts.min() >= 374  # stratified: 375 per bin, +-1
    cell, n_cells = street_cells(city, poses[:, :2])
    assert np.all(cell >= 0)
    hits = np.bincount(cell, minlength=n_cells)
    assert np.all(hits > 0), np.flatnonzero(hits == 0)
    # and every (cell, heading bin) pair of the intersections, where the view changes fastest
    k2 = len(city.street_centers) ** 2
    bins = ((poses[:, 2] + np.pi) // (np.pi / 4)).astype(int)
    pairs = {(c, b) for c, b in zip(cell, bins) if c < k2}
    assert len(pairs) == 8 * k2


def test_corners_are_weighted_up(city):
    uniform = coverage_poses(city, 4000, np.random.default_rng(2), corner_weight=0.0)
    weighted = coverage_poses(city, 4000, np.random.default_rng(2), corner_weight=2.0)
    share_u = corner_mask(city, uniform[:, :2]).mean()
    share_w = corner_mask(city, weighted[:, :2]).mean()
    # density x3 in the corner zones: odds x3 (binomial sd of a share ~0.008)
    odds = (share_w / (1 - share_w)) / (share_u / (1 - share_u))
    assert 2.5 < odds < 3.6, (share_u, share_w)


def test_free_region_reaches_off_the_asphalt(city):
    poses = coverage_poses(city, 3000, np.random.default_rng(3), region="free")
    assert np.all(city.free_mask(poses[:, :2], 0.32))
    assert not np.all(street_mask(city, poses[:, :2], 0.32, "streets"))  # pavements, lots


def test_same_seed_same_poses(city):
    a = coverage_poses(city, 500, np.random.default_rng(7))
    b = coverage_poses(city, 500, np.random.default_rng(7))
    c = coverage_poses(city, 500, np.random.default_rng(8))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_bad_inputs_get_clear_errors(city):
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="n"):
        coverage_poses(city, 0, rng)
    with pytest.raises(TypeError, match="rng"):
        coverage_poses(city, 10, 0)
    with pytest.raises(ValueError, match="region"):
        coverage_poses(city, 10, rng, region="lanes")
    with pytest.raises(ValueError, match="corner_weight"):
        coverage_poses(city, 10, rng, corner_weight=-1.0)
    with pytest.raises(ValueError, match="margin"):
        coverage_poses(city, 10, rng, margin=float("nan"))
    with pytest.raises(RuntimeError, match="too narrow"):
        coverage_poses(city, 10, rng, margin=3.0)  # wider than a street
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        street_mask(city, np.zeros((3, 3)))


def test_coverage_mode_is_reached_driving_and_deterministic(env):
    images, poses = collect_dataset(env, 60, "coverage", seed=4, progress=False)
    assert images.shape == (60, 32, 32, 3) and poses.shape == (60, 3)
    assert np.all(env.city.free_mask(poses[:, :2], 0.2))
    assert len({img.tobytes() for img in images}) == 60
    again = collect_dataset(env, 60, "coverage", seed=4, progress=False)
    assert np.array_equal(images, again[0]) and np.array_equal(poses, again[1])
    targets = coverage_poses(env.city, 60, np.random.default_rng(4), margin=POSE_MARGIN)
    assert np.max(np.hypot(*(poses[:, :2] - targets[:, :2]).T)) < 0.05  # reached


def test_coverage_mode_options(env):
    _, poses = collect_dataset(env, 30, "coverage", seed=0, progress=False, region="free",
                               corner_weight=0.0)
    assert poses.shape == (30, 3)
    with pytest.raises(ValueError, match="coverage option"):
        collect_dataset(env, 5, "coverage", progress=False, lanes="route")
    with pytest.raises(ValueError, match="lane option"):
        collect_dataset(env, 5, "lanes", progress=False, region="free")


def test_coverage_mode_margin_reaches_closer_to_buildings(env):
    _, default = collect_dataset(env, 300, "coverage", seed=1, progress=False)
    _, close = collect_dataset(env, 300, "coverage", seed=1, progress=False, margin=0.24)
    assert np.all(env.city.free_mask(close[:, :2], 0.22))
    assert not np.all(env.city.free_mask(close[:, :2], POSE_MARGIN - 0.02))  # nearer walls
    assert np.all(env.city.free_mask(default[:, :2], POSE_MARGIN - 0.02))
    with pytest.raises(ValueError, match="margin"):  # the robot would be inside a building
        collect_dataset(env, 5, "coverage", progress=False, margin=0.1)


def test_off_lane_waypoints_leave_the_lanes_and_turn_back(city):
    wp = off_lane_waypoints(city, 200.0, np.random.default_rng(0))
    assert np.all(street_mask(city, wp, 0.32))
    c = city.street_centers
    lateral = np.min(np.abs(np.abs(wp[:, :, None] - c).min(axis=2)), axis=1)
    assert np.mean(lateral > 0.3) > 0.3  # off the centrelines (lanes are +-0.3 m)
    seg = np.diff(wp, axis=0)
    cross = seg[:-1, 0] * seg[1:, 1] - seg[:-1, 1] * seg[1:, 0]
    turn = np.abs(np.arctan2(cross, np.sum(seg[:-1] * seg[1:], axis=1)))
    assert np.any(turn > 2.8)  # U-turns
    assert np.sum(np.hypot(*seg.T)) >= 200.0


def test_drive_off_lane_turns_on_the_spot_and_stays_free(env):
    images, poses, controls = drive_off_lane(env, 400, seed=1, progress=False)
    assert images.shape == (401, 32, 32, 3) and poses.shape == (401, 3)
    assert controls.shape == (400, 2)
    assert np.all(env.city.free_mask(poses[:, :2], 0.15))
    spin = (controls[:, 0] == 0) & (np.abs(controls[:, 1]) > 0)
    assert spin.mean() > 0.05 and (~spin).mean() > 0.5
    again = drive_off_lane(env, 400, seed=1, progress=False)
    assert np.array_equal(poses, again[1]) and np.array_equal(controls, again[2])


def test_off_lane_pilot_bad_inputs():
    with pytest.raises(ValueError, match="waypoints"):
        OffLanePilot(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="speed"):
        OffLanePilot(np.zeros((3, 2)), speed=0.0)
    pilot = OffLanePilot(np.array([[0.0, 0.0], [1.0, 0.0]]))
    assert np.array_equal(pilot(np.array([1.0, 0.0, 0.0])), [0.0, 0.0])  # done: stands
