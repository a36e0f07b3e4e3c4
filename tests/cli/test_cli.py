"""``appearance-nav``: every ``--help`` runs, bad options are usage errors (exit status 2,
the message names the option) raised before any work starts, and a real command runs."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from localization.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
       "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _cli(*argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "localization.cli", *argv], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=timeout, check=False)


def test_top_level_help_lists_every_command() -> None:
    proc = _cli("--help")
    assert proc.returncode == 0, proc.stderr
    for name in COMMANDS:
        assert name in proc.stdout


@pytest.mark.parametrize("command", list(COMMANDS))
def test_command_help(command: str) -> None:
    """(``fit`` and ``predict`` come from another branch: they fail until it is merged.)"""
    proc = _cli(command, "--help")
    assert proc.returncode == 0, proc.stderr
    assert f"appearance-nav {command}" in proc.stdout
    assert "--" in proc.stdout


def test_no_command_is_a_usage_error() -> None:
    proc = _cli()
    assert proc.returncode == 2
    assert "command" in proc.stderr


# ------------------------------------------------------------------- bad command-line input
#: (argv, the option the message must name); {file}, {dir} and {missing} are replaced by an
#: existing file, an existing folder and a path that does not exist
BAD = [
    # track
    ("track --steps 0", "--steps"),
    ("track --steps -5", "--steps"),
    ("track --steps abc", "--steps"),
    ("track --n-train 0", "--n-train"),
    ("track --n-drive -1", "--n-drive"),
    ("track --measurements bogus", "--measurements"),
    ("track --measurements pose,,features", "--measurements"),
    ("track --starts a,b", "--starts"),
    ("track --starts 0,-1", "--starts"),
    ("track --lanes nowhere", "--lanes"),
    ("track --camera pinhole", "--camera"),
    ("track --image-size 0", "--image-size"),
    ("track --motion-noise -0.1", "--motion-noise"),
    ("track --motion-noise nan", "--motion-noise"),
    ("track --scene-seed -1", "--scene-seed"),
    ("track --localizer {missing}", "--localizer"),
    ("track --localizer {dir}", "--localizer"),
    ("track --out {file}", "--out"),
    # collect
    ("collect --n 0", "--n"),
    ("collect --n -3", "--n"),
    ("collect --mode spiral", "--mode"),
    ("collect --camera foo", "--camera"),
    ("collect --height 0", "--height"),
    ("collect --width -2", "--width"),
    ("collect --n-headings 0", "--n-headings"),
    ("collect --seed -1", "--seed"),
    ("collect --motion-noise inf", "--motion-noise"),
    ("collect --conditions dawn", "--conditions"),
    ("collect --out {dir}", "--out"),
    ("collect --out {file}/data.npz", "--out"),
    ("collect --out {dir}/new/", "--out"),
    ("collect --bogus 1", "--bogus"),
    # demo
    ("demo --n-route 0", "--n-route"),
    ("demo --strip 0", "--strip"),
    ("demo --lanes sideways", "--lanes"),
    ("demo --dusk noon", "--dusk"),
    ("demo --episodes -1", "--episodes"),
    ("demo --steps 0", "--steps"),
    ("demo --n-train 0", "--n-train"),
    ("demo --out {file}", "--out"),
    # train
    ("train --pose-source gps", "--pose-source"),
    ("train --localizer {missing}", "--localizer"),
    ("train --pose-source oracle --measurement foo", "--measurement"),
    ("train --pose-source oracle --start anywhere", "--start"),
    ("train --pose-source oracle --vec-env threads", "--vec-env"),
    ("train --pose-source oracle --total-timesteps 0", "--total-timesteps"),
    ("train --pose-source oracle --n-envs 0", "--n-envs"),
    ("train --pose-source oracle --batch-size -1", "--batch-size"),
    ("train --pose-source oracle --threads 0", "--threads"),
    ("train --pose-source oracle --out {file}", "--out"),
    # eval
    ("eval --agents foo", "--agents"),
    ("eval --sources gps", "--sources"),
    ("eval --sources=", "--sources"),
    ("eval --localizer {missing}", "--localizer"),
    ("eval --sources oracle --episodes 0", "--episodes"),
    ("eval --sources oracle --max-episode-steps -1", "--max-episode-steps"),
    ("eval --sources oracle --start x", "--start"),
    ("eval --sources oracle --camera nope", "--camera"),
    # reproduce
    ("reproduce --cameras pinhole", "--cameras"),
    ("reproduce --features sift", "--features"),
    ("reproduce --datasets lanes", "--datasets"),
    ("reproduce --cv 1", "--cv"),
    ("reproduce --n 10", "--n"),
    ("reproduce --n-components 0", "--n-components"),
    ("reproduce --ground-range -1", "--ground-range"),
    ("reproduce --pixel-smooth -0.5", "--pixel-smooth"),
    ("reproduce --out {file}", "--out"),
    # bench
    ("bench --only foo", "--only"),
    ("bench --only=", "--only"),
    ("bench --only env --env-sizes 0", "--env-sizes"),
    ("bench --only env --env-sizes a", "--env-sizes"),
    ("bench --only env --env-steps 0", "--env-steps"),
    ("bench --only env --env-out-dir {file}", "--env-out-dir"),
    ("bench --only gse --gse-ns 1", "--gse-ns"),
    ("bench --only gse --gse-m 0", "--gse-m"),
    ("bench --only gse --gse-out {file}/bench", "--gse-out"),
    ("bench --only filter --filter-runs 0", "--filter-runs"),
    ("bench --only filter --filter-motion-noise -1", "--filter-motion-noise"),
    ("bench --only agents --agents-eval-cities a", "--agents-eval-cities"),
    ("bench --only agents --agents-localizers {file}", "--agents-localizers"),
    ("bench --only agents --agents-vec-env x", "--agents-vec-env"),
    ("bench --only agents --agents-active-penalty -1", "--agents-active-penalty"),
    ("bench --gse-worker-n 5", "--gse-worker-n"),
]


@pytest.fixture
def paths(tmp_path: Path) -> dict[str, str]:
    (tmp_path / "a_file.txt").write_text("not a folder")
    (tmp_path / "a_dir").mkdir()
    return {"file": str(tmp_path / "a_file.txt"), "dir": str(tmp_path / "a_dir"),
            "missing": str(tmp_path / "missing.npz")}


def test_at_least_forty_bad_inputs() -> None:
    assert len(BAD) >= 40


@pytest.mark.parametrize(("argv", "option"), BAD, ids=[a for a, _ in BAD])
def test_bad_option_is_a_usage_error(argv: str, option: str, paths: dict[str, str],
                                     monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture) -> None:
    args = argv.format(**paths).split()
    command = importlib.import_module(f"localization.cli.{args[0]}")

    def never(_: object) -> None:
        raise AssertionError(f"{argv!r} reached run(): the bad option was not caught")

    monkeypatch.setattr(command, "run", never)
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "error: " in err, err
    message = err.split("error: ", 1)[1]
    assert option in message.split()[0:3] or option in message, err


# ------------------------------------------------------------------------------- real runs
def test_collect_writes_a_dataset(tmp_path: Path) -> None:
    out = tmp_path / "nested" / "grid.npz"
    proc = _cli("collect", "--mode", "random", "--n", "6", "--height", "24", "--width", "32",
                "--seed", "3", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    import envs

    images, poses, meta = envs.load_dataset(out)
    assert images.shape == (6, 24, 32, 3) and images.dtype == np.uint8
    assert poses.shape == (6, 3) and np.all(np.isfinite(poses))
    assert meta["n"] == 6 and meta["mode"] == "random" and meta["seed"] == 3


def test_bench_gse_runs_its_scaling_workers(tmp_path: Path) -> None:
    """The GSE benchmark's workers run as ``python -m`` subprocesses of the workflow module."""
    out = tmp_path / "gse"
    proc = _cli("bench", "--only", "gse", "--gse-ns", "200,300", "--gse-skip-accuracy",
                "--gse-skip-scalable", "--gse-skip-incremental",
                "--gse-latency-repeats", "3", "--gse-batch-size", "50", "--gse-out", str(out))
    assert proc.returncode == 0, proc.stderr
    result = json.loads(out.with_suffix(".json").read_text())
    assert [r["n"] for r in result["scaling"]] == [200, 300]
    assert all("fit_s" in r for r in result["scaling"]), result["scaling"]
    assert "| 300 |" in out.with_suffix(".md").read_text()


def test_bench_robustness_names_a_missing_policy(tmp_path) -> None:
    """A PPO policy file that does not exist is named before any benchmark starts."""
    import subprocess
    import sys

    missing = tmp_path / "policy.pt"
    run = subprocess.run([sys.executable, "-m", "localization.cli", "bench", "--only", "robustness",
                          "--robustness-belief-policy", str(missing)],
                         capture_output=True, text=True, check=False)
    assert run.returncode == 2 and "--robustness-belief-policy: no such file" in run.stderr
