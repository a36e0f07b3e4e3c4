"""Options shared by ``fit`` and ``predict`` for recorded data (:mod:`localization.recorded`)."""

from __future__ import annotations

from pathlib import Path

from localization.cli._args import UsageError
from localization.recorded import MATCHES, Recording, load_recorded


def parse_size(text: str, option: str = "--resize") -> tuple[int, int] | None:
    """``"HxW"`` (or ``"N"`` for N x N) -> (height, width); ``""`` -> None."""
    if not text:
        return None
    parts = text.lower().split("x")
    try:
        size = tuple(int(p) for p in parts)
    except ValueError:
        size = ()
    if len(size) == 1:
        size = size * 2
    if len(size) != 2 or min(size) < 1:
        raise UsageError(option, f"must be HEIGHTxWIDTH (e.g. 48x64) or one positive integer, "
                                 f"got {text!r}")
    return size  # type: ignore[return-value]


def check_data_options(data: str, pose_file: str, match: str, resize: str
                       ) -> tuple[Path, Path | None, tuple[int, int] | None]:
    """Validate ``--data``, ``--pose-file``, ``--match`` and ``--resize`` (no file is read)."""
    if not data:
        raise UsageError("data", "is required: a folder of images with a TUM pose file, or a .npz")
    path = Path(data)
    if not path.exists():
        raise UsageError("data", f"no folder or file at {path}")
    if path.is_file() and path.suffix != ".npz":
        raise UsageError("data", f"{path} must be a folder of images or a .npz dataset")
    if pose_file and not Path(pose_file).is_file():
        raise UsageError("pose-file", f"no file at {pose_file}")
    if match not in MATCHES:
        raise UsageError("match", f"must be one of {', '.join(MATCHES)}, got {match!r}")
    size = parse_size(resize)
    if path.is_file() and (pose_file or size):
        raise UsageError("pose-file", "and --resize apply to image folders, not to a .npz")
    return path, Path(pose_file) if pose_file else None, size


def load_data(data: str, pose_file: str, match: str, resize: str, max_difference: float,
              require_poses: bool) -> Recording:
    """:func:`load_recorded` with the command-line options, printing what was read."""
    path, poses, size = check_data_options(data, pose_file, match, resize)
    rec = load_recorded(path, poses, resize=size, match=match, max_difference=max_difference,
                        require_poses=require_poses)
    h, w = rec.images.shape[1:3]
    what = "without poses" if rec.poses is None else "with poses"
    print(f"read {len(rec.images)} images {h}x{w} {what} from {path}", flush=True)
    return rec


def check_out(out: str, suffix: str, option: str = "--out") -> Path:
    """The output file ``out`` (its folder created); ``suffix`` ('' for any) must match."""
    if not out:
        raise UsageError(option, "must name a file")
    path = Path(out)
    if suffix and path.suffix != suffix:
        raise UsageError(option, f"must end in {suffix}, got {out!r}")
    if path.is_dir():
        raise UsageError(option, f"{out} is a folder; name a file")
    path.parent.mkdir(parents=True, exist_ok=True)
    return path
