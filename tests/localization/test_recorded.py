"""Recorded data: TUM files, image folders, association, the .npz format and bad files."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from localization import load_recorded, read_tum, write_tum
from localization.recorded import (
    associate,
    load_dataset,
    quaternion_from_yaw,
    read_images,
    save_dataset,
    yaw_from_quaternion,
)

RNG = np.random.default_rng(0)


def _images(n: int, h: int = 12, w: int = 16, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (n, h, w, 3), dtype=np.uint8)


def _folder(tmp: Path, n: int = 5, names: list[str] | None = None, *, t0: float = 100.0,
            dt: float = 0.1, pose_name: str = "poses.txt") -> tuple[Path, np.ndarray, np.ndarray]:
    """A folder of n PNGs named by timestamp (or ``names``) and a TUM file of their poses."""
    images = _images(n)
    times = t0 + dt * np.arange(n)
    names = names or [f"{t:.6f}" for t in times]
    for name, img in zip(names, images):
        Image.fromarray(img).save(tmp / f"{name}.png")
    poses = np.column_stack([RNG.uniform(-5, 5, (n, 2)), RNG.uniform(-3, 3, n)])
    write_tum(tmp / pose_name, times, poses)
    return tmp, images, poses


def _tum_line(t: float, yaw: float, roll: float = 0.0, pitch: float = 0.0) -> str:
    q = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()  # [qx, qy, qz, qw]
    return f"{t} 1.0 2.0 0.5 " + " ".join(f"{v:.12f}" for v in q)


# ----------------------------------------------------------------------- quaternions, TUM
@pytest.mark.parametrize("yaw", [0.0, 0.3, np.pi / 2, -np.pi / 2, 2.5, -2.9, np.pi - 1e-9])
def test_yaw_from_quaternion_known_angles(yaw):
    q = Rotation.from_euler("z", yaw).as_quat()
    assert yaw_from_quaternion(q)[0] == pytest.approx(yaw, abs=1e-12)
    assert np.allclose(quaternion_from_yaw(yaw)[0], q, atol=1e-12)
    assert yaw_from_quaternion(-q)[0] == pytest.approx(yaw, abs=1e-12)  # q and -q: one rotation


def test_yaw_is_read_with_small_roll_and_pitch(tmp_path):
    f = tmp_path / "p.txt"
    f.write_text("\n".join(_tum_line(i, yaw, roll, pitch) for i, (yaw, roll, pitch) in
                           enumerate([(1.0, 0.1, -0.05), (-2.0, -0.15, 0.15), (3.0, 0.0, 0.19)])))
    t, poses = read_tum(f)
    assert np.array_equal(t, [0, 1, 2])
    assert np.allclose(poses, [[1, 2, 1.0], [1, 2, -2.0], [1, 2, 3.0]], atol=1e-9)


def test_tum_round_trip_comments_blank_lines_and_z(tmp_path):
    t = np.array([1305031102.175304, 1305031102.211214, 1305031102.275326])
    poses = np.array([[0.1, -2.0, 0.0], [1.5, 3.25, np.pi - 0.01], [-4.0, 0.5, -1.2]])
    path = write_tum(tmp_path / "sub" / "traj.txt", t, poses, comment="made by a test\nline 2")
    text = path.read_text()
    assert text.startswith("# timestamp tx ty tz qx qy qz qw\n# made by a test\n# line 2\n")
    path.write_text(text.replace("\n", "\n\n   # an indented comment\n", 1))
    t2, poses2 = read_tum(path)
    assert np.allclose(t2, t, atol=1e-6, rtol=0) and np.allclose(poses2, poses, atol=1e-6)
    lifted = tmp_path / "z.txt"  # tz is ignored
    lifted.write_text(text.replace(" 0 0.0", " 7.5 0.0"))
    assert np.allclose(read_tum(lifted)[1], poses, atol=1e-6)


def test_write_tum_refuses_nan_and_mismatch(tmp_path):
    with pytest.raises(ValueError, match="finite"):
        write_tum(tmp_path / "a.txt", [0.0], [[np.nan, 0, 0]])
    with pytest.raises(ValueError, match="match"):
        write_tum(tmp_path / "a.txt", [0.0, 1.0], [[0, 0, 0]])


# ----------------------------------------------------------------------- association
def test_associate_nearest_within_tolerance_each_pose_once():
    poses_t = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
    images_t = np.array([0.305, 0.004, 0.196, 0.11, 0.9, 0.195])  # 0.9: no pose; 0.195 vs 0.196
    i_img, i_pose = associate(images_t, poses_t, max_difference=0.02)
    assert i_img.tolist() == [0, 1, 2, 3] and i_pose.tolist() == [3, 0, 2, 1]
    assert associate([5.0], poses_t)[0].size == 0


def test_folder_matched_by_timestamp(tmp_path):
    folder, images, poses = _folder(tmp_path, 6)
    (folder / "100.200000.png").unlink()  # an image missing: its pose is not used
    Image.fromarray(_images(1)[0]).save(folder / "200.000000.png")  # an image without a pose
    (folder / "100.300000.png").rename(folder / "100.312000.png")  # 12 ms late: still matched
    rec = load_recorded(folder)
    assert rec.images.shape == (5, 12, 16, 3) and rec.images.dtype == np.uint8
    assert rec.poses.shape == (5, 3)
    assert np.allclose(rec.timestamps, [100.0, 100.1, 100.312, 100.4, 100.5])  # the images'
    for img, pose, k in zip(rec.images, rec.poses, [0, 1, 3, 4, 5]):
        assert np.array_equal(img, images[k]) and np.allclose(pose, poses[k], atol=1e-6)
    every = load_recorded(folder, require_poses=False)  # for predicting: every image
    assert np.allclose(every.timestamps, [*rec.timestamps, 200.0])
    assert np.array_equal(every.images[:5], rec.images)
    assert np.array_equal(every.poses[:5], rec.poses) and np.isnan(every.poses[5]).all()


def test_folder_matched_in_order_when_names_are_not_numbers(tmp_path):
    names = [f"frame_{i:03d}" for i in range(4)]
    folder, images, poses = _folder(tmp_path, 4, names, pose_name="groundtruth.txt")
    rec = load_recorded(folder)
    assert np.array_equal(rec.images, images) and np.allclose(rec.poses, poses, atol=1e-6)
    assert np.allclose(rec.timestamps, 100.0 + 0.1 * np.arange(4))


def test_timestamp_names_come_in_time_order(tmp_path):
    folder, images, poses = _folder(tmp_path, 3, ["1.5", "1.25", "10"], t0=0.0)
    write_tum(folder / "poses.txt", [1.25, 1.5, 10.0], poses)
    rec = load_recorded(folder, require_poses=False)
    assert np.array_equal(rec.timestamps, [1.25, 1.5, 10.0])
    assert np.array_equal(rec.images, images[[1, 0, 2]]) and np.allclose(rec.poses, poses)


def test_order_is_natural(tmp_path):
    names = ["frame_9", "frame_10", "frame_100", "frame_11"]
    folder, images, poses = _folder(tmp_path, 4, names)
    # the pose file lists frames 9, 10, 100, 11: sorted naturally, 9, 10, 11, 100
    write_tum(folder / "poses.txt", np.arange(4.0), poses[[0, 1, 3, 2]])
    rec = load_recorded(folder)
    assert np.array_equal(rec.images, images[[0, 1, 3, 2]])
    assert np.allclose(rec.poses, poses[[0, 1, 3, 2]], atol=1e-6)


def test_numeric_names_can_be_matched_in_order(tmp_path):
    folder, images, _ = _folder(tmp_path, 3, ["000001", "000002", "000003"])
    with pytest.raises(ValueError, match="no image within"):
        load_recorded(folder)
    rec = load_recorded(folder, match="order")
    assert np.array_equal(rec.images, images)


def test_images_without_poses_and_rgb_subfolder(tmp_path):
    (tmp_path / "rgb").mkdir()
    _, images, _ = _folder(tmp_path / "rgb", 3)
    rec = load_recorded(tmp_path, require_poses=False)
    assert rec.poses is None and np.array_equal(rec.images, images)
    assert np.allclose(rec.timestamps, [100.0, 100.1, 100.2])
    rec = load_recorded(tmp_path, tmp_path / "rgb" / "poses.txt")
    assert np.array_equal(rec.images, images) and rec.poses.shape == (3, 3)


def test_modes_converted_to_rgb_and_resize(tmp_path):
    rgb = _images(1, 8, 10)[0]
    Image.fromarray(rgb).save(tmp_path / "a.png")
    Image.fromarray(rgb[..., 0]).save(tmp_path / "b.png")  # grayscale L
    Image.fromarray(np.dstack([rgb, np.full(rgb.shape[:2], 7, np.uint8)])).save(tmp_path / "c.png")
    Image.fromarray(rgb).convert("P").save(tmp_path / "d.png")
    smooth = np.dstack([*np.meshgrid(np.arange(10) * 20, np.arange(8) * 25),
                        np.full((8, 10), 128)]).astype(np.uint8)
    Image.fromarray(smooth).save(tmp_path / "e.JPG", quality=95)
    files = sorted(tmp_path.glob("*"))
    out = read_images(files)
    assert out.shape == (5, 8, 10, 3) and out.dtype == np.uint8
    assert np.array_equal(out[0], rgb) and np.array_equal(out[2], rgb)  # alpha dropped
    assert np.array_equal(out[1], np.repeat(rgb[..., :1], 3, axis=2))
    assert np.abs(out[4].astype(int) - smooth).mean() < 5  # JPEG: lossy
    assert read_images(files, resize=(4, 6)).shape == (5, 4, 6, 3)


def test_npz_through_load_recorded(tmp_path):
    images, poses = _images(4), RNG.normal(size=(4, 3))
    path = save_dataset(tmp_path / "d", images, poses, source="test")
    assert path.suffix == ".npz"
    rec = load_recorded(path)
    assert np.array_equal(rec.images, images) and np.array_equal(rec.poses, poses)
    assert np.array_equal(rec.timestamps, np.arange(4.0))
    assert load_dataset(path)[2] == {"source": "test"}


# ----------------------------------------------------------------------- bad files
def _write(tmp: Path, name: str, text: str) -> Path:
    (tmp / name).write_text(text)
    return tmp / name


GOOD = "1.0 0 0 0 0 0 0 1\n"


def _tum(text: str) -> Callable[[Path], tuple[Callable[[], object], str]]:
    def make(tmp: Path) -> tuple[Callable[[], object], str]:
        f = _write(tmp, "poses.txt", text)
        return (lambda: read_tum(f)), str(f)
    return make


def _corrupt_image(data: bytes, name: str = "100.000000.png"):
    def make(tmp: Path):
        folder, _, _ = _folder(tmp, 3)
        (folder / name).write_bytes(data)
        return (lambda: load_recorded(folder)), str(folder / name)
    return make


def _png_bytes(mode: str, size=(16, 12)) -> bytes:
    import io
    buf = io.BytesIO()
    Image.new(mode, size).save(buf, format="PNG")
    return buf.getvalue()


def _noise_png() -> bytes:
    import io
    buf = io.BytesIO()
    Image.fromarray(_images(1, 64, 64)[0]).save(buf, format="PNG")
    return buf.getvalue()


def _other_size(tmp: Path):
    folder, _, _ = _folder(tmp, 3)
    Image.fromarray(_images(1, 20, 16)[0]).save(folder / "100.100000.png")
    return (lambda: load_recorded(folder)), str(folder / "100.100000.png")


def _no_images(tmp: Path):
    write_tum(tmp / "poses.txt", [0.0], [[0, 0, 0]])
    return (lambda: load_recorded(tmp)), str(tmp)


def _no_pose_file(tmp: Path):
    folder, _, _ = _folder(tmp, 3)
    (folder / "poses.txt").unlink()
    return (lambda: load_recorded(folder)), str(folder)


def _given_pose_file_missing(tmp: Path):
    folder, _, _ = _folder(tmp, 3)
    return (lambda: load_recorded(folder, tmp / "nope.txt")), str(tmp / "nope.txt")


def _no_match(tmp: Path):
    folder, _, _ = _folder(tmp, 3)
    write_tum(folder / "poses.txt", [5000.0, 5001.0], [[0, 0, 0], [1, 0, 0]])
    return (lambda: load_recorded(folder)), str(folder / "poses.txt")


def _count_mismatch(tmp: Path):
    folder, _, _ = _folder(tmp, 3, ["a", "b", "c"])
    write_tum(folder / "poses.txt", [0.0, 1.0], [[0, 0, 0], [1, 0, 0]])
    return (lambda: load_recorded(folder)), str(folder / "poses.txt")


def _timestamp_match_on_names(tmp: Path):
    folder, _, _ = _folder(tmp, 3, ["a", "b", "c"])
    return (lambda: load_recorded(folder, match="timestamp")), str(folder)


def _bad_pose_in_folder(tmp: Path):
    folder, _, _ = _folder(tmp, 3)
    f = _write(folder, "poses.txt", GOOD + "2.0 0 0 0 0 0 0\n")
    return (lambda: load_recorded(folder)), f"{f}, line 2"


def _missing_path(tmp: Path):
    return (lambda: load_recorded(tmp / "absent")), str(tmp / "absent")


def _not_npz(tmp: Path):
    f = _write(tmp, "data.csv", "1,2,3")
    return (lambda: load_recorded(f)), str(f)


def _npz(data: bytes | None = None, **arrays):
    def make(tmp: Path):
        f = tmp / "d.npz"
        if data is not None:
            f.write_bytes(data)
        else:
            np.savez(f, **arrays)
        return (lambda: load_recorded(f)), str(f)
    return make


def _binary_pose_file(tmp: Path):
    f = tmp / "p.txt"
    f.write_bytes(b"\xff\xfe\x00\x81garbage")
    return (lambda: read_tum(f)), str(f)


def _directory_as_pose_file(tmp: Path):
    (tmp / "poses.txt").mkdir()
    return (lambda: read_tum(tmp / "poses.txt")), str(tmp / "poses.txt")


BAD = {  # name -> (maker, exception type, extra text that the message must contain)
    "tum missing": (lambda t: ((lambda: read_tum(t / "x.txt")), str(t / "x.txt")),
                    FileNotFoundError, "no pose file"),
    "tum empty": (_tum(""), ValueError, "no poses"),
    "tum only comments": (_tum("# timestamp tx ty tz qx qy qz qw\n\n# nothing\n"), ValueError,
                          "no poses"),
    "tum 7 columns": (_tum(GOOD + "2.0 0 0 0 0 0 1\n"), ValueError, "line 2"),
    "tum 9 columns": (_tum("# c\n1.0 0 0 0 0 0 0 1 5\n"), ValueError, "line 2"),
    "tum 3 columns (x y yaw)": (_tum("1.0 2.0 0.5\n"), ValueError, "8 columns"),
    "tum not a number": (_tum(GOOD + GOOD.replace("1.0", "2.0") + "3.0 0 x 0 0 0 0 1\n"),
                         ValueError, "line 3"),
    "tum NaN": (_tum(GOOD + "2.0 nan 0 0 0 0 0 1\n"), ValueError, "line 2"),
    "tum inf": (_tum(GOOD + "2.0 0 inf 0 0 0 0 1\n"), ValueError, "NaN or inf"),
    "tum duplicate timestamp": (_tum(GOOD + "2.0 0 0 0 0 0 0 1\n" + GOOD), ValueError,
                                "line 3"),
    "tum zero quaternion": (_tum("1.0 0 0 0 0 0 0 0\n"), ValueError, "quaternion"),
    "tum quaternion length 2": (_tum("1.0 0 0 0 0 0 0 2\n"), ValueError, "line 1"),
    "tum rolled": (_tum(GOOD + _tum_line(2.0, 0.5, roll=0.3) + "\n"), ValueError, "line 2"),
    "tum pitched": (_tum(_tum_line(2.0, -1.0, pitch=-0.25) + "\n"), ValueError, "pitch"),
    "tum camera optical frame": (_tum(_tum_line(2.0, 0.0, roll=-np.pi / 2) + "\n"),
                                 ValueError, "optical"),
    "tum binary": (_binary_pose_file, ValueError, "text"),
    "tum is a folder": (_directory_as_pose_file, ValueError, "text"),
    "image random bytes": (_corrupt_image(b"\x89PNG\r\n\x1a\nnot really"), ValueError,
                           "corrupt"),
    "image empty file": (_corrupt_image(b""), ValueError, "corrupt"),
    "image truncated": (_corrupt_image(_noise_png()[:6000]), ValueError, "corrupt"),
    "image is text": (_corrupt_image(b"hello", "100.000000.png"), ValueError, "corrupt"),
    "image 16-bit": (_corrupt_image(_png_bytes("I;16")), ValueError, "16-bit"),
    "image other size": (_other_size, ValueError, "differs"),
    "folder without images": (_no_images, ValueError, "no images"),
    "folder without pose file": (_no_pose_file, FileNotFoundError, "poses.txt"),
    "given pose file missing": (_given_pose_file_missing, FileNotFoundError, "pose file"),
    "no image matched": (_no_match, ValueError, "no image within"),
    "counts differ": (_count_mismatch, ValueError, "3 images but 2 poses"),
    "timestamp match, names not numbers": (_timestamp_match_on_names, ValueError, "numbers"),
    "bad pose file in folder": (_bad_pose_in_folder, ValueError, "8 columns"),
    "path missing": (_missing_path, FileNotFoundError, "no recorded data"),
    "file not npz": (_not_npz, ValueError, "folder of images or a .npz"),
    "npz corrupt": (_npz(b"PK\x03\x04 broken zip"), ValueError, "corrupted"),
    "npz without poses": (_npz(images=_images(2), meta=np.array("{}")), ValueError, "lacks"),
    "npz float images": (_npz(images=np.zeros((2, 4, 4, 3)), poses=np.zeros((2, 3)),
                              meta=np.array("{}")), ValueError, "uint8"),
    "npz string poses": (_npz(images=_images(2), poses=np.full((2, 3), "a"),
                              meta=np.array("{}")), ValueError, "real numbers"),
    "npz NaN poses": (_npz(images=_images(2), poses=np.full((2, 3), np.nan),
                           meta=np.array("{}")), ValueError, "NaN"),
    "npz object array": (_npz(images=np.array([None, 1], dtype=object), poses=np.zeros((2, 3)),
                              meta=np.array("{}")), ValueError, "corrupted"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_files_name_the_file(tmp_path, case):
    maker, error, text = BAD[case]
    call, where = maker(tmp_path)
    with pytest.raises(error) as info:
        call()
    message = str(info.value)
    assert where in message, f"{case}: {message!r} does not name {where}"
    assert text in message, f"{case}: {message!r} lacks {text!r}"


@pytest.mark.parametrize("resize", [(0, 4), (4,), "4x4", (2.5, 4), (4, -1), 4])
def test_bad_resize(tmp_path, resize):
    _folder(tmp_path, 2)
    with pytest.raises(ValueError, match="resize"):
        load_recorded(tmp_path, resize=resize)


def test_bad_match_and_npz_options(tmp_path):
    with pytest.raises(ValueError, match="match"):
        load_recorded(tmp_path, match="nearest")
    path = save_dataset(tmp_path / "d.npz", _images(2), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="image folders only"):
        load_recorded(path, resize=(4, 4))
