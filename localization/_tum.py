"""TUM trajectory files as planar poses (see :mod:`localization.recorded` for the format)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["MAX_TILT", "quaternion_from_yaw", "read_tum", "write_tum", "yaw_from_quaternion"]

MAX_TILT = 0.2  # rad: largest roll or pitch of a planar pose
_UNIT_TOL = 0.1  # largest | |q| - 1 | of a TUM quaternion


# --------------------------------------------------------------------------- quaternions
def yaw_from_quaternion(q: ArrayLike) -> NDArray[np.float64]:
    """Yaw about z (rad, in [-pi, pi]) of unit quaternions ``q`` (n, 4) ``[qx, qy, qz, qw]``."""
    x, y, z, w = np.asarray(q, dtype=np.float64).reshape(-1, 4).T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _roll_pitch(q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    x, y, z, w = q.T
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    return roll, pitch


def quaternion_from_yaw(yaw: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternions (n, 4) ``[qx, qy, qz, qw]`` of rotations by ``yaw`` (n,) about z."""
    half = 0.5 * np.asarray(yaw, dtype=np.float64).reshape(-1)
    zero = np.zeros_like(half)
    return np.stack([zero, zero, np.sin(half), np.cos(half)], axis=1)


# --------------------------------------------------------------------------- TUM files
def read_tum(path: str | Path, max_tilt: float = MAX_TILT
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Read a TUM trajectory file as planar poses.

    Parameters
    ----------
    path : str or Path
    max_tilt : float
        Largest roll or pitch (rad) accepted.

    Returns
    -------
    timestamps : ndarray (n,) float64
    poses : ndarray (n, 3) float64 ``[x, y, yaw]`` (yaw in [-pi, pi])

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is unreadable or empty, or a line has not 8 numbers, has NaN or inf, a
        quaternion far from unit length, roll or pitch beyond ``max_tilt``, or a timestamp
        seen before (the message names the file and the line).
    """
    path = Path(path)
    rows, lines = [], []
    for number, line in enumerate(_text_lines(path), start=1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if len(fields) != 8:
            raise ValueError(f"{path}, line {number}: expected 8 columns 'timestamp tx ty tz "
                             f"qx qy qz qw', got {len(fields)}: {line[:80]!r}")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise ValueError(f"{path}, line {number}: not a number in {line[:80]!r}") from None
        lines.append(number)
    if not rows:
        raise ValueError(f"{path}: no poses (the file is empty or only comments)")
    data, lines = np.array(rows), np.array(lines)
    _check_rows(path, data, lines, max_tilt)
    q = data[:, 4:] / np.linalg.norm(data[:, 4:], axis=1, keepdims=True)
    return data[:, 0], np.column_stack([data[:, 1:3], yaw_from_quaternion(q)])


def _text_lines(path: Path) -> list[str]:
    if not path.exists():
        raise FileNotFoundError(f"no pose file at {path}")
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: not a readable text file ({err})") from None


def _check_rows(path: Path, data: NDArray[np.float64], lines: NDArray[np.int_],
                max_tilt: float) -> None:
    """Finite values, unit quaternions, level poses and unique timestamps, or ValueError."""
    bad = ~np.isfinite(data).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}, line {lines[bad][0]}: NaN or inf")
    norm = np.linalg.norm(data[:, 4:], axis=1)
    bad = np.abs(norm - 1.0) > _UNIT_TOL
    if bad.any():
        raise ValueError(f"{path}, line {lines[bad][0]}: quaternion qx qy qz qw has length "
                         f"{norm[bad][0]:.3g}, not 1")
    roll, pitch = _roll_pitch(data[:, 4:] / norm[:, None])
    bad = np.maximum(np.abs(roll), np.abs(pitch)) > max_tilt
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{path}, line {lines[i]}: roll {roll[i]:.3f} rad, pitch "
                         f"{pitch[i]:.3f} rad: not a planar pose (|roll|, |pitch| <= "
                         f"{max_tilt} rad; a camera optical frame must be converted to the "
                         "body frame, z up)")
    order = np.argsort(data[:, 0], kind="stable")
    same = np.flatnonzero(np.diff(data[order, 0]) == 0)
    if len(same):
        first, again = sorted(lines[order[[same[0], same[0] + 1]]])
        raise ValueError(f"{path}, line {again}: timestamp {float(data[order[same[0]], 0])!r} "
                         f"already on line {first}")


def write_tum(path: str | Path, timestamps: ArrayLike, poses: ArrayLike,
              comment: str = "") -> Path:
    """Write planar poses as a TUM trajectory file (``tz = 0``, the quaternion of the yaw).

    Parameters
    ----------
    path : str or Path
        The file; its folder is created.
    timestamps : array_like (n,)
    poses : array_like (n, 3) ``[x, y, yaw]``; finite (drop rows without a pose first).
    comment : str
        Extra ``#`` lines written after the header.

    Returns
    -------
    Path
    """
    t = np.asarray(timestamps, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    if t.ndim != 1 or poses.shape != (len(t), 3):
        raise ValueError(f"timestamps (n,) and poses (n, 3) must match, got {t.shape} and "
                         f"{poses.shape}")
    if not (np.isfinite(t).all() and np.isfinite(poses).all()):
        raise ValueError("timestamps and poses must be finite (drop the rows without a pose)")
    q = quaternion_from_yaw(poses[:, 2])
    header = ["# timestamp tx ty tz qx qy qz qw"] + [f"# {c}" for c in comment.splitlines()]
    body = [f"{ti:.6f} {x:.6f} {y:.6f} 0 {qx:.9f} {qy:.9f} {qz:.9f} {qw:.9f}"
            for ti, (x, y, _), (qx, qy, qz, qw) in zip(t, poses, q)]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(header + body) + "\n")
    return path
