"""Recorded data from disk: image folders, TUM trajectory files and our ``.npz`` datasets.

numpy and Pillow only (no simulator, no torch), so a localizer can be fitted on, and predict
for, images recorded by a real robot.

Formats
-------
TUM trajectory (``poses.txt``, ``groundtruth.txt``): one pose a line,
``timestamp tx ty tz qx qy qz qw`` (seconds, metres, a unit quaternion of the body frame's
orientation in the world frame, z up), blank lines and lines starting with ``#`` ignored.
The planar pose ``[x, y, yaw]`` takes ``tx, ty`` and the yaw about z of the quaternion
(Z-Y-X Euler angles); ``tz`` is ignored. A pose whose roll or pitch is more than
``max_tilt`` (0.2 rad) from level is refused: a camera's *optical* frame (z forward) has a
roll of -pi/2 and must be converted to the body frame (x forward, z up) first.

Image folder: PNG or JPEG files (``.png``, ``.jpg``, ``.jpeg``, any case) in the folder, or in
its ``rgb/`` subfolder (the TUM RGB-D layout), read in natural name order (``frame_2``
before ``frame_10``). All must share one
size (or pass ``resize``). Grayscale, palette and RGBA images are converted to RGB (the
alpha channel is dropped, not blended); 16-bit and float images (depth maps) are refused.
Images are matched to poses by the timestamp in the file name stem
(``1305031102.175304.png``): each image to the pose nearest in time if within
``max_difference`` seconds (0.02 s, like TUM's ``associate.py``), each pose used at most once;
images without a pose are dropped for fitting (kept with NaN poses for predicting); images
named by timestamp come in time order. When the stems are not all numbers, images are matched to
poses in order (sorted names against the pose file's lines), which needs equal counts.

``.npz`` dataset (:func:`save_dataset` / :func:`load_dataset`, also exported by :mod:`envs`):
``images`` (n, H, W, 3) uint8, ``poses`` (n, 3) float64 ``[x, y, yaw]`` and ``meta`` (a JSON
string), loaded with ``allow_pickle=False``.

Every bad file raises an error (FileNotFoundError or ValueError) naming the file, and the
line for text files.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from localization._tum import (
    MAX_TILT,
    quaternion_from_yaw,
    read_tum,
    write_tum,
    yaw_from_quaternion,
)

__all__ = ["IMAGE_SUFFIXES", "POSE_FILES", "Recording", "associate", "list_images",
           "load_dataset", "load_recorded", "quaternion_from_yaw", "read_images", "read_tum",
           "save_dataset", "write_tum", "yaw_from_quaternion"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
POSE_FILES = ("poses.txt", "groundtruth.txt")  # looked for in a folder, in this order
MAX_DIFFERENCE = 0.02  # s: largest time between an image and its pose (TUM's associate.py)
MATCHES = ("auto", "timestamp", "order")


class Recording(NamedTuple):
    """Images with their poses, as :func:`load_recorded` returns them."""

    images: NDArray[np.uint8]  # (n, H, W, 3)
    poses: NDArray[np.float64] | None  # (n, 3) [x, y, yaw]; None without a pose file
    timestamps: NDArray[np.float64]  # (n,) seconds (the image index when there are none)


# --------------------------------------------------------------------------- images
def list_images(folder: str | Path) -> list[Path]:
    """PNG/JPEG files of ``folder`` (or of its ``rgb/`` subfolder when it has none), in
    natural order (numbers in names compare as numbers)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no image folder at {folder}")
    for where in (folder, folder / "rgb"):
        files = sorted((p for p in where.glob("*") if p.suffix.lower() in IMAGE_SUFFIXES),
                       key=_natural_key)
        if files:
            return files
    raise ValueError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in it or in its rgb/")


def read_images(files: list[Path], resize: tuple[int, int] | None = None
                ) -> NDArray[np.uint8]:
    """Read image files into (n, H, W, 3) uint8, converted to RGB, optionally resized.

    Parameters
    ----------
    files : list of Path
    resize : (height, width), optional
        Resize every image (bilinear); without it all must have the first one's size.

    Raises
    ------
    ValueError
        For an unreadable, corrupt or 16-bit/float image, or one whose size differs.
    """
    if resize is not None:
        resize = _check_resize(resize)
    if not files:
        raise ValueError("no image files given")
    first = _read_image(Path(files[0]), resize)
    out = np.empty((len(files), *first.shape), np.uint8)
    out[0] = first
    for i, f in enumerate(files[1:], start=1):
        img = _read_image(Path(f), resize)
        if img.shape != first.shape:
            raise ValueError(f"{f}: image size {img.shape[0]}x{img.shape[1]} (HxW) differs from "
                             f"{first.shape[0]}x{first.shape[1]} of {files[0]}; pass resize")
        out[i] = img
    return out


def _natural_key(path: Path) -> list[Any]:
    """``frame_2.png`` before ``frame_10.png``: digit runs compare as numbers."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def _check_resize(resize: Any) -> tuple[int, int]:
    try:
        h, w = (int(s) for s in resize)
        ok = (h, w) == tuple(resize) and h >= 1 and w >= 1
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"resize must be (height, width) positive integers, got {resize!r}")
    return h, w


def _read_image(path: Path, resize: tuple[int, int] | None) -> NDArray[np.uint8]:
    from PIL import Image  # here: importing envs (which re-exports the .npz format) skips it

    try:
        with Image.open(path) as img:
            img.load()
            mode = img.mode
            img = img.convert("RGB")
    except FileNotFoundError:
        raise FileNotFoundError(f"no image at {path}") from None
    except Exception as err:  # noqa: BLE001  (PIL: UnidentifiedImageError, OSError, ...)
        raise ValueError(f"{path}: unreadable or corrupt image ({type(err).__name__}: {err})"
                         ) from None
    if mode in ("I", "F") or mode.startswith("I;"):
        raise ValueError(f"{path}: {mode} image (16-bit or float, a depth map?); want 8-bit")
    if resize is not None:
        img = img.resize((resize[1], resize[0]), Image.Resampling.BILINEAR)
    return np.asarray(img, dtype=np.uint8)


def associate(image_times: ArrayLike, pose_times: ArrayLike,
              max_difference: float = MAX_DIFFERENCE
              ) -> tuple[NDArray[np.int_], NDArray[np.int_]]:
    """Match images to poses by time, like TUM's ``associate.py``.

    Candidate pairs (image, nearest pose) closer than ``max_difference`` are taken in order
    of increasing time difference, each pose at most once.

    Returns
    -------
    image_index, pose_index : ndarray (k,) int
        Matched pairs, sorted by image index.
    """
    ti = np.asarray(image_times, dtype=np.float64)
    tp = np.asarray(pose_times, dtype=np.float64)
    order = np.argsort(tp)
    pos = np.clip(np.searchsorted(tp[order], ti), 1, max(len(tp) - 1, 1))
    left, right = order[pos - 1], order[np.minimum(pos, len(tp) - 1)]
    nearest = np.where(np.abs(tp[left] - ti) <= np.abs(tp[right] - ti), left, right)
    diff = np.abs(tp[nearest] - ti)
    img_idx, pose_idx, used = [], [], set()
    for i in np.argsort(diff, kind="stable"):
        if diff[i] <= max_difference and nearest[i] not in used:
            used.add(int(nearest[i]))
            img_idx.append(int(i))
            pose_idx.append(int(nearest[i]))
    pairs = sorted(zip(img_idx, pose_idx))
    return (np.array([p[0] for p in pairs], dtype=int), np.array([p[1] for p in pairs], dtype=int))


def _stem_times(files: list[Path]) -> NDArray[np.float64] | None:
    """Timestamps from the file name stems, or None unless all are finite numbers."""
    try:
        t = np.array([float(f.stem) for f in files])
    except ValueError:
        return None
    return t if np.isfinite(t).all() else None


# --------------------------------------------------------------------------- load_recorded
def load_recorded(path: str | Path, pose_file: str | Path | None = None, *,
                  resize: tuple[int, int] | None = None, match: str = "auto",
                  max_difference: float = MAX_DIFFERENCE, max_tilt: float = MAX_TILT,
                  require_poses: bool = True) -> Recording:
    """Load recorded images and poses: an image folder with a TUM pose file, or our ``.npz``.

    Parameters
    ----------
    path : str or Path
        A folder of images (see the module docstring) or a ``.npz`` of :func:`save_dataset`.
    pose_file : str or Path, optional
        The TUM file (folders only); default ``poses.txt`` or ``groundtruth.txt`` in ``path``.
    resize : (height, width), optional
        Resize the images (folders only).
    match : {"auto", "timestamp", "order"}
        How images meet poses: by the timestamps of the file name stems, by order, or
        "auto" (timestamps when every stem is a number).
    max_difference : float
        Largest time (s) between an image and its pose.
    max_tilt : float
        Largest roll or pitch (rad) of a pose.
    require_poses : bool
        True (for fitting): a pose file is needed, and images without a pose are dropped.
        False (for predicting): every image is returned, with NaN pose rows for images
        without a pose, or ``poses=None`` when there is no pose file.

    Returns
    -------
    Recording
        ``images`` (n, H, W, 3) uint8, ``poses`` (n, 3) float64 or None, ``timestamps`` (n,)
        float64: the images' (from their names), the pose file's when matched in order, or
        the image index (a ``.npz``, or names that are not numbers without a pose file).
    """
    path = Path(path)
    if match not in MATCHES:
        raise ValueError(f"match must be one of {MATCHES}, got {match!r}")
    if not path.exists():
        raise FileNotFoundError(f"no recorded data at {path}")
    if path.is_file():
        if path.suffix != ".npz":
            raise ValueError(f"{path}: recorded data must be a folder of images or a .npz")
        if pose_file is not None or resize is not None:
            raise ValueError("pose_file and resize apply to image folders only")
        images, poses, _ = load_dataset(path)
        return Recording(images, poses, np.arange(len(images), dtype=np.float64))
    files = list_images(path)
    stamps = _stem_times(files) if match != "order" else None
    if match == "timestamp" and stamps is None:
        raise ValueError(f"{path}: match='timestamp' but image names are not all numbers")
    if stamps is not None:  # in time order ("1.5" before "1.25" by name)
        order = np.argsort(stamps, kind="stable")
        files, stamps = [files[i] for i in order], stamps[order]
    pose_file = _find_pose_file(path, pose_file, require_poses)
    if pose_file is None:
        stamps = np.arange(len(files), dtype=np.float64) if stamps is None else stamps
        return Recording(read_images(files, resize), None, stamps)
    times, poses = read_tum(pose_file, max_tilt)
    i_img, i_pose = _match(path, stamps, times, max_difference, pose_file)
    if stamps is None:  # matched in order: the pose file's times
        stamps = times
    if require_poses:  # images without a pose are dropped
        return Recording(read_images([files[i] for i in i_img], resize), poses[i_pose],
                         stamps[i_img])
    out = np.full((len(files), 3), np.nan)
    out[i_img] = poses[i_pose]
    return Recording(read_images(files, resize), out, stamps)


def _find_pose_file(folder: Path, pose_file: str | Path | None, required: bool) -> Path | None:
    if pose_file is not None:
        if not Path(pose_file).is_file():
            raise FileNotFoundError(f"no pose file at {pose_file}")
        return Path(pose_file)
    found = [folder / n for n in POSE_FILES if (folder / n).is_file()]
    if not found and required:
        raise FileNotFoundError(f"{folder}: no pose file ({' or '.join(POSE_FILES)}); "
                                "pass one")
    return found[0] if found else None


def _match(folder: Path, stamps: NDArray[np.float64] | None, times: NDArray[np.float64],
           max_difference: float, pose_file: Path
           ) -> tuple[NDArray[np.int_], NDArray[np.int_]]:
    """Images (their stem times, or None: in order) to the poses at ``times``."""
    if stamps is None:
        n = len(list_images(folder))
        if n != len(times):
            raise ValueError(f"{folder}: {n} images but {len(times)} poses in {pose_file}; "
                             "images named by timestamp can be matched, others need one pose "
                             "per image")
        return np.arange(n), np.arange(n)
    i_img, i_pose = associate(stamps, times, max_difference)
    if not len(i_img):
        raise ValueError(f"{folder}: no image within {max_difference} s of a pose of "
                         f"{pose_file} (image times {stamps.min():.6f}..{stamps.max():.6f}, "
                         f"poses {times.min():.6f}..{times.max():.6f}); images named by "
                         "frame number need match='order'")
    return i_img, i_pose


# --------------------------------------------------------------------------- .npz datasets
def save_dataset(path: str | Path, images: NDArray[np.uint8], poses: NDArray[np.float64],
                 **meta: Any) -> Path:
    """Save to a compressed ``.npz`` with ``images``, ``poses`` and ``meta`` (a JSON string).

    Raises
    ------
    ValueError
        On mismatched shapes/dtypes or metadata that is not JSON-serialisable.
    """
    images, poses = _check_arrays(np.asarray(images), np.asarray(poses), str(path))
    try:
        meta_json = json.dumps(meta, sort_keys=True)
    except TypeError as err:
        raise ValueError(f"dataset metadata must be JSON-serialisable: {err}") from None
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, images=images, poses=poses, meta=np.array(meta_json))
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def load_dataset(path: str | Path
                 ) -> tuple[NDArray[np.uint8], NDArray[np.float64], dict[str, Any]]:
    """Load ``(images, poses, meta)`` saved by :func:`save_dataset`.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is not a readable npz, lacks an array, or the arrays are inconsistent.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no dataset at {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in ("images", "poses", "meta") if k in z.files}
    except Exception as err:  # zipfile.BadZipFile, OSError, EOFError, zlib errors, pickled data...
        raise ValueError(f"dataset {path} is corrupted or not an npz file: {err}") from err
    missing = [k for k in ("images", "poses", "meta") if k not in arrays]
    if missing:
        raise ValueError(f"dataset {path} lacks arrays {missing}")
    images, poses, meta_json = arrays["images"], arrays["poses"], str(arrays["meta"])
    try:
        meta = json.loads(meta_json)
    except json.JSONDecodeError as err:
        raise ValueError(f"dataset {path} has corrupted metadata: {err}") from None
    images, poses = _check_arrays(images, poses, str(path))
    return images, poses, meta


def _check_arrays(images: NDArray[Any], poses: NDArray[Any], where: str
                  ) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"{where}: images must be (n, H, W, 3) uint8, got {images.shape} "
                         f"{images.dtype}")
    if poses.shape != (len(images), 3) or poses.dtype.kind not in "biuf":
        raise ValueError(f"{where}: poses must be real numbers of shape ({len(images)}, 3), got "
                         f"{poses.shape} {poses.dtype}")
    if not np.all(np.isfinite(poses)):
        raise ValueError(f"{where}: poses contain NaN or inf")
    return images, poses.astype(np.float64)

