"""Estimate the poses of recorded images with a saved localizer and write them to a file.

``--data`` is a folder of PNG/JPEG images (a pose file in it, if any, is read as ground
truth) or a ``.npz`` dataset; see ``localization.recorded`` for the formats. The images must
have the size the localizer was fitted on (``--resize HEIGHTxWIDTH`` as in ``fit``).

    appearance-nav predict --localizer results/run1.npz --data recordings/run2 \\
        --resize 48x64 --out results/run2_poses.txt

Output, ``--format tum`` (default): one TUM line a pose, ``timestamp x y 0 qx qy qz qw``
(the quaternion of the yaw about z); the timestamp is the image's (from its file name, from
the pose file when images are matched in order, or the image index). Every image is
predicted, also those without a ground-truth pose. Images whose features
lie outside the localizer's training domain get no pose: their lines are left out, and
their number is printed and written in a ``#`` comment at the top of the file.
``--format npz``: arrays ``timestamps`` (n,) and ``poses`` (n, 3) ``[x, y, yaw]`` for every
image, NaN rows for those outside the domain (``np.load(..., allow_pickle=False)``).

When the data has poses, the median position and heading errors are printed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from localization.cli._args import UsageError, check_non_negative
from localization.cli._recorded import check_data_options, check_out, load_data
from localization.recorded import MAX_DIFFERENCE, write_tum
from localization.turned_views import check_turn_camera

if TYPE_CHECKING:
    from localization.localizer import AppearanceLocalizer

FORMATS = ("tum", "npz")


@dataclass
class Args:
    localizer: str = field(default="results/localizer.npz", metadata={
        "help": "a localizer saved by 'appearance-nav fit'"})
    data: str = field(default="", metadata={
        "help": "recorded images: a folder (a TUM pose file in it is ground truth) or a .npz"})
    pose_file: str = field(default="", metadata={
        "help": "ground-truth TUM pose file of a folder (default: its poses.txt or "
                "groundtruth.txt, if any)"})
    match: str = field(default="auto", metadata={
        "help": "images to poses: 'timestamp' (file names), 'order', or 'auto'"})
    max_difference: float = field(default=MAX_DIFFERENCE, metadata={
        "help": "largest time (s) between an image and its ground-truth pose"})
    resize: str = field(default="", metadata={
        "help": "resize the folder's images to HEIGHTxWIDTH (as when fitting)"})
    turns: int = field(default=0, metadata={
        "help": "perspective camera: each position the median over the image and its views "
                "turned by 1..turns pixels either way (AppearanceLocalizer.predict(turns=...); "
                "2 in the appearance benchmark)"})
    format: str = field(default="tum", metadata={"help": "output format: tum or npz"})
    out: str = field(default="results/poses.txt", metadata={
        "help": "output file (its folder is created)"})


def load_checked(args: Args) -> tuple[AppearanceLocalizer, Path]:
    """Validate the options and load the localizer (fast), before reading any image."""
    from localization.loading import load_localizer

    if args.format not in FORMATS:
        raise UsageError("format", f"must be one of {', '.join(FORMATS)}, got {args.format!r}")
    check_data_options(args.data, args.pose_file, args.match, args.resize)
    if not Path(args.localizer).is_file():
        raise UsageError("localizer", f"no file at {args.localizer} (write one with "
                                "'appearance-nav fit')")
    check_non_negative("turns", args.turns)
    out = check_out(args.out, ".npz" if args.format == "npz" else "")
    loc = load_localizer(args.localizer)
    if args.turns:
        try:
            check_turn_camera(loc.camera_)
        except ValueError as err:
            raise UsageError("turns", f"{err} ({args.localizer})") from None
    return loc, out


def report_errors(estimate: NDArray[np.float64], truth: NDArray[np.float64]) -> None:
    """Print the median position and heading errors of the rows with an estimate and a
    true pose."""
    ok = np.all(np.isfinite(estimate), axis=1) & np.all(np.isfinite(truth), axis=1)
    if not ok.any():
        return
    pos = np.hypot(*(estimate[ok, :2] - truth[ok, :2]).T)
    yaw = np.abs(np.angle(np.exp(1j * (estimate[ok, 2] - truth[ok, 2]))))
    print(f"against the data's poses: median position error {np.median(pos):.3f} m, "
          f"median heading error {np.median(yaw):.3f} rad ({ok.sum()} images)")


def run(args: Args) -> None:
    """Predict and write the poses."""
    loc, out = load_checked(args)
    rec = load_data(args.data, args.pose_file, args.match, args.resize, args.max_difference,
                    require_poses=False)
    if tuple(rec.images.shape[1:3]) != tuple(loc.image_size_):
        h, w = loc.image_size_
        raise UsageError("data", f"images are {rec.images.shape[1]}x{rec.images.shape[2]} "
                         f"(HxW) but {args.localizer} was fitted on {h}x{w}; pass "
                         f"--resize {h}x{w}")
    t0 = time.perf_counter()
    poses = loc.predict(rec.images, turns=args.turns)
    ok = np.all(np.isfinite(poses), axis=1)
    print(f"estimated {ok.sum()} of {len(poses)} poses in {time.perf_counter() - t0:.1f} s; "
          f"{(~ok).sum()} images outside the localizer's domain")
    if rec.poses is not None:
        report_errors(poses, rec.poses)
    if args.format == "npz":
        np.savez_compressed(out, timestamps=rec.timestamps, poses=poses)
    else:
        note = (f"{(~ok).sum()} of {len(poses)} images outside the localizer's domain: "
                "no line" if (~ok).any() else "")
        write_tum(out, rec.timestamps[ok], poses[ok], comment=f"appearance-nav predict "
                  f"--localizer {args.localizer} --data {args.data}\n{note}".rstrip())
    print(f"wrote {out}")
