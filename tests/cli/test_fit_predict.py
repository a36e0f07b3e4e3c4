"""``appearance-nav fit`` and ``predict`` end to end on recorded data written to disk.

A small city (12 m, 32x32 images) gives two folders of PNGs named by timestamp with TUM pose
files: lane images around the route to fit on, and a drive around the route (its own seed,
motion noise) to predict. The commands run as a user runs them (``python -m
localization.cli``); the test reads the TUM file that ``predict`` wrote.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from localization import read_tum, write_tum

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000.0  # s: the recording's start time


def _write_folder(folder: Path, images: np.ndarray, poses: np.ndarray, dt: float,
                  jitter: float = 0.0) -> np.ndarray:
    """PNGs named ``<timestamp>.png`` and ``poses.txt``; the pose clock is ``jitter`` s off."""
    folder.mkdir(parents=True)
    times = T0 + dt * np.arange(len(images))
    for t, img in zip(times, images):
        Image.fromarray(img).save(folder / f"{t:.6f}.png")
    write_tum(folder / "poses.txt", times + jitter, poses)
    return times


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """(fit folder, predict folder, the predict folder's true poses and image times)."""
    from envs import AppearanceNavEnv, collect_dataset

    root = tmp_path_factory.mktemp("recorded")
    env = AppearanceNavEnv(scene_seed=0, image_size=(32, 32), city_size=12.0, motion_noise=0.05)
    try:
        train = collect_dataset(env, 400, "lanes", seed=0, progress=False, lanes="route")
        test = collect_dataset(env, 150, "route", seed=1, progress=False)
    finally:
        env.close()
    _write_folder(root / "train", *train, dt=0.1)
    times = _write_folder(root / "drive", *test, dt=env.dt, jitter=0.004)
    return root / "train", root / "drive", test[1], times


@pytest.fixture(scope="module")
def small_localizer(recorded, tmp_path_factory):
    """A localizer fitted on the fit folder resized to 16x16 (the folders hold 32x32)."""
    from localization import AppearanceLocalizer, load_recorded

    path = tmp_path_factory.mktemp("small") / "small.npz"
    images, poses, _ = load_recorded(recorded[0], resize=(16, 16))
    with warnings.catch_warnings():  # GSE's eigen-gap warning: the fit is not under test
        warnings.simplefilter("ignore", RuntimeWarning)
        AppearanceLocalizer(noise_folds=0).fit(images, poses).save(path)
    return path


def _cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.run([sys.executable, "-m", "localization.cli", *args], cwd=ROOT, env=env,
                          check=False, capture_output=True, text=True, timeout=300)


def test_fit_then_predict_recorded_folders(recorded, tmp_path):
    train, drive, true_poses, times = recorded
    loc = tmp_path / "models" / "loc.npz"  # the folder does not exist yet
    fit = _cli("fit", "--data", str(train), "--features", "pixel_pca", "--n-components", "16",
               "--noise-folds", "0", "--out", str(loc))  # no K-fold noise: not under test
    assert fit.returncode == 0, fit.stderr
    assert "read 400 images 32x32 with poses" in fit.stdout and loc.is_file()

    out = tmp_path / "est" / "poses.txt"
    pred = _cli("predict", "--localizer", str(loc), "--data", str(drive), "--out", str(out))
    assert pred.returncode == 0, pred.stderr
    assert "median position error" in pred.stdout  # the folder's poses.txt is ground truth
    t, est = read_tum(out)
    # every image predicted (or counted out of the domain), timestamps the images' own
    assert len(t) >= 0.9 * len(times)
    idx = np.searchsorted(times, t)
    assert np.allclose(times[idx], t, atol=1e-6, rtol=0)
    err = np.hypot(*(est[:, :2] - true_poses[idx, :2]).T)
    yaw_err = np.abs(np.angle(np.exp(1j * (est[:, 2] - true_poses[idx, 2]))))
    # measured: median 0.143 m, heading 0.004 rad (the mean training position is ~5.8 m off)
    assert np.median(err) < 0.3, np.median(err)
    assert np.median(yaw_err) < 0.05, np.median(yaw_err)

    npz = tmp_path / "est.npz"
    assert _cli("predict", "--localizer", str(loc), "--data", str(drive), "--format", "npz",
                "--out", str(npz)).returncode == 0
    with np.load(npz, allow_pickle=False) as z:
        assert z["poses"].shape == (len(times), 3) and np.allclose(z["timestamps"], times)
        ok = np.isfinite(z["poses"]).all(axis=1)
        assert np.allclose(z["poses"][ok][:, :2], est[:, :2], atol=1e-5)


@pytest.mark.parametrize(("args", "message"), [
    (["predict", "--data", "{drive}", "--localizer", "{tmp}/none.npz"], "--localizer"),
    (["predict", "--data", "{drive}", "--localizer", "{loc}"], "--resize 16x16"),
    (["predict", "--data", "{tmp}/missing", "--localizer", "{loc}"], "--data"),
    (["predict", "--data", "{drive}", "--format", "csv", "--localizer", "{loc}"], "--format"),
    (["predict", "--data", "{drive}", "--turns", "-1", "--localizer", "{loc}"], "--turns"),
    (["predict", "--data", "{drive}", "--format", "npz", "--out", "{tmp}/p.txt",
      "--localizer", "{loc}"], ".npz"),
    (["fit", "--data", "{drive}", "--features", "sift"], "--features"),
    (["fit", "--data", "{drive}", "--resize", "0x4"], "--resize"),
    (["fit", "--data", "{drive}", "--match", "nearest"], "--match"),
    (["fit", "--data", "{drive}", "--out", "{tmp}/loc.txt"], ".npz"),
    (["fit", "--data", "{drive}", "--pose-file", "{tmp}/nope.txt"], "--pose-file"),
    (["fit", "--lanes", "highway"], "--lanes"),
    (["fit", "--districts", "0"], "--districts"),
    (["fit", "--overlap", "-1"], "--overlap"),
])
def test_bad_options_fail_fast(recorded, small_localizer, tmp_path, args, message, capsys):
    """Bad options are refused with an error naming them, before any long work."""
    from localization.cli import main

    argv = [a.format(drive=recorded[1], tmp=tmp_path, loc=small_localizer) for a in args]
    if "--out" not in args:
        argv += ["--out", str(tmp_path / ("o.npz" if args[0] == "fit" else "o.txt"))]
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def test_predict_leaves_out_images_outside_the_domain(recorded, small_localizer, tmp_path,
                                                      monkeypatch, capsys):
    """Rows the localizer cannot place (NaN) get no TUM line, a count, and NaN in the npz;
    --resize brings the folder's 32x32 images to the localizer's 16x16."""
    from localization import AppearanceLocalizer
    from localization.cli import main

    predict = AppearanceLocalizer.predict

    def some_outside(self, images, **options):
        poses = predict(self, images, **options)
        poses[[0, 5, 7]] = np.nan
        return poses

    monkeypatch.setattr(AppearanceLocalizer, "predict", some_outside)
    _, drive, _, times = recorded
    out = tmp_path / "p.txt"
    main(["predict", "--localizer", str(small_localizer), "--data", str(drive),
          "--resize", "16x16", "--out", str(out)])
    assert "3 images outside the localizer's domain" in capsys.readouterr().out
    assert "# 3 of 150 images outside the localizer's domain: no line" in out.read_text()
    t, _ = read_tum(out)
    assert np.allclose(t, np.delete(times, [0, 5, 7]), atol=1e-6, rtol=0)
    main(["predict", "--localizer", str(small_localizer), "--data", str(drive),
          "--resize", "16x16", "--format", "npz", "--out", str(tmp_path / "p.npz")])
    with np.load(tmp_path / "p.npz", allow_pickle=False) as z:
        assert np.flatnonzero(np.isnan(z["poses"]).any(axis=1)).tolist() == [0, 5, 7]


def test_predict_with_turns_writes_the_turned_estimate(recorded, small_localizer, tmp_path):
    """--turns 1 writes AppearanceLocalizer.predict(images, turns=1)."""
    from localization.cli import main

    _, drive, _, _ = recorded
    out = tmp_path / "t.npz"
    main(["predict", "--localizer", str(small_localizer), "--data", str(drive),
          "--resize", "16x16", "--format", "npz", "--turns", "1", "--out", str(out)])
    main(["predict", "--localizer", str(small_localizer), "--data", str(drive),
          "--resize", "16x16", "--format", "npz", "--out", str(tmp_path / "p.npz")])
    with np.load(out, allow_pickle=False) as z, np.load(tmp_path / "p.npz",
                                                        allow_pickle=False) as p:
        turned, plain = z["poses"], p["poses"]
    assert np.array_equal(np.isnan(turned), np.isnan(plain))
    assert np.array_equal(turned[:, 2], plain[:, 2], equal_nan=True)
    live = np.isfinite(plain).all(axis=1)
    assert not np.allclose(turned[live, :2], plain[live, :2])


def test_predict_refuses_turns_for_a_wide_camera(recorded, small_localizer, tmp_path, capsys):
    """--turns needs a perspective localizer: a fisheye one is refused, naming --turns."""
    from localization.cli import main
    from localization.loading import load_localizer

    loc = load_localizer(small_localizer)
    loc.camera_ = "fisheye"
    loc.save(tmp_path / "fisheye.npz")
    with pytest.raises(SystemExit) as info:
        main(["predict", "--localizer", str(tmp_path / "fisheye.npz"), "--data",
              str(recorded[1]), "--resize", "16x16", "--turns", "1",
              "--out", str(tmp_path / "p.txt")])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--turns" in err and "fisheye" in err
