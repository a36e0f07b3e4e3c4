"""collect_dataset modes and the .npz round trip with clear errors."""

import numpy as np
import pytest

from envs import AppearanceNavEnv, collect_dataset, load_dataset, save_dataset
from envs.datasets import PurePursuit, drive_route, drive_streets, grid_poses


@pytest.fixture(scope="module")
def env():
    e = AppearanceNavEnv(scene_seed=0, image_size=(32, 32))
    yield e
    e.close()


@pytest.mark.parametrize("mode", ["grid", "random", "route", "lanes"])
def test_collect_shapes_and_free_poses(env, mode):
    images, poses = collect_dataset(env, 40, mode, seed=0, progress=False)
    assert images.shape == (40, 32, 32, 3) and images.dtype == np.uint8
    assert poses.shape == (40, 3) and poses.dtype == np.float64
    assert np.all(np.abs(poses[:, 2]) <= np.pi)
    assert all(env.city.is_free(x, y, 0.2) for x, y, _ in poses)
    assert len({img.tobytes() for img in images}) > 30  # images vary with the pose


def test_collect_is_deterministic(env):
    for mode in ("random", "route", "lanes"):
        a = collect_dataset(env, 20, mode, seed=3, progress=False)
        b = collect_dataset(env, 20, mode, seed=3, progress=False)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_route_drives_around_the_loop(env):
    _, poses = collect_dataset(env, 300, "route", seed=0, progress=False)
    steps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    assert np.all(steps < 0.15) and steps.sum() > 10.0  # continuous and moving (~0.5 m/s)


def test_grid_is_regular():
    from envs.scene import generate_city

    city = generate_city(0)
    poses = grid_poses(city, 400, n_headings=8)
    assert poses.shape == (400, 3)
    xs = np.unique(np.round(poses[:, 0], 6))
    assert np.allclose(np.diff(xs), np.diff(xs)[0])  # one spacing
    assert len(np.unique(np.round(poses[:, 2], 6))) == 8


def test_bad_mode_and_n(env):
    with pytest.raises(ValueError, match="grid"):
        collect_dataset(env, 10, "spiral")
    with pytest.raises(ValueError, match="positive"):
        collect_dataset(env, 0, "random")


def test_npz_round_trip(tmp_path, env):
    images, poses = collect_dataset(env, 10, "random", seed=1, progress=False)
    path = save_dataset(tmp_path / "d.npz", images, poses, mode="random", scene_seed=0)
    images2, poses2, meta = load_dataset(path)
    assert np.array_equal(images, images2) and np.array_equal(poses, poses2)
    assert meta == {"mode": "random", "scene_seed": 0}


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_dataset(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(ValueError, match="corrupted"):
        load_dataset(bad)
    partial = tmp_path / "partial.npz"
    np.savez_compressed(partial, images=np.zeros((2, 16, 16, 3), np.uint8))
    with pytest.raises(ValueError, match="lacks"):
        load_dataset(partial)
    truncated = tmp_path / "truncated.npz"
    save_dataset(truncated, np.zeros((5, 16, 16, 3), np.uint8), np.zeros((5, 3)))
    truncated.write_bytes(truncated.read_bytes()[:-40])
    with pytest.raises(ValueError, match="corrupted"):
        load_dataset(truncated)


def test_save_validates(tmp_path):
    with pytest.raises(ValueError, match="uint8"):
        save_dataset(tmp_path / "x.npz", np.zeros((2, 16, 16, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="poses"):
        save_dataset(tmp_path / "x.npz", np.zeros((2, 16, 16, 3), np.uint8), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="JSON"):
        save_dataset(tmp_path / "x.npz", np.zeros((2, 16, 16, 3), np.uint8), np.zeros((2, 3)), bad=object())


def test_lanes_are_reached_driving(env):
    """The "lanes" frames are taken from a moving robot: it pitches, a teleported one does not."""
    images, poses = collect_dataset(env, 30, "lanes", seed=2, progress=False, lanes="route",
                                    lateral=0.1, heading=0.05)
    assert np.linalg.norm(env.data.qvel[:2]) > 0.4  # still rolling at cruise speed
    env.set_pose(poses[-1])
    assert not np.array_equal(env.render_camera(), images[-1])
    with pytest.raises(ValueError, match="lanes"):
        collect_dataset(env, 5, "random", lanes="route")
    with pytest.raises(ValueError, match="lanes"):
        collect_dataset(env, 5, "lanes", lanes="highway")


def test_drive_route_records_controls(env):
    images, poses, controls = drive_route(env, 50, seed=1, start=200, progress=False)
    assert images.shape == (51, 32, 32, 3) and poses.shape == (51, 3)
    assert controls.shape == (50, 2)
    assert np.all(np.abs(controls) <= 1.0)
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    assert np.all(step < 0.1) and step[5:].mean() > 0.04
    again = drive_route(env, 50, seed=1, start=200, progress=False)
    assert all(np.array_equal(a, b) for a, b in zip((images, poses, controls), again))


def test_drive_streets_follows_the_streets(env):
    images, poses, controls = drive_streets(env, 300, seed=4, progress=False)
    assert images.shape == (301, 32, 32, 3) and controls.shape == (300, 2)
    assert env.city.free_mask(poses[:, :2], 0.2).all()
    street = np.abs(poses[:, :2, None] - env.city.street_centers[None, None]).min(axis=2)
    assert np.all(street.min(axis=1) < 0.4)  # on a lane
    assert np.hypot(*np.diff(poses[:, :2], axis=0).T).sum() > 0.8 * 300 * env.dt * 0.6
    again = drive_streets(env, 300, seed=4, progress=False)
    assert all(np.array_equal(a, b) for a, b in zip((images, poses, controls), again))
    with pytest.raises(ValueError, match="positive"):
        drive_streets(env, 0, progress=False)


def test_open_pure_pursuit_stops_at_the_end():
    pilot = PurePursuit(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]), closed=False)
    assert pilot.path[-1] == pytest.approx([2.0, 2.0])
    assert pilot.start_pose(10_000) == pytest.approx([2.0, 2.0, np.pi / 2])  # the last point
    pose = pilot.start_pose(0)
    assert pose == pytest.approx([0.0, 0.0, 0.0])
    for _ in range(200):  # drive it with a perfect unicycle
        v, w = pilot(pose)
        pose = pose + 0.1 * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), w])
    assert np.hypot(pose[0] - 2.0, pose[1] - 2.0) < 0.5  # it never runs on past the end
