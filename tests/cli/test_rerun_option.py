"""``--rerun FILE.rrd`` on ``track``, ``eval`` and ``demo``: bad paths and a missing rerun-sdk
are usage errors (exit 2, naming the option) before any work; a real ``eval`` writes a
recording that Rerun's reader opens."""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

import pytest

from localization.cli import main

from .test_cli import _cli

BAD = [
    ("track --rerun {dir}/out.txt", "--rerun"),
    ("track --rerun {dir}", "--rerun"),
    ("eval --sources oracle --rerun {file}/x.rrd", "--rerun"),
    ("eval --sources oracle --rerun-episodes -1", "--rerun-episodes"),
    ("demo --rerun {dir}/", "--rerun"),
]


def _usage_error(argv: list[str], monkeypatch: pytest.MonkeyPatch,
                 capsys: pytest.CaptureFixture) -> str:
    command = importlib.import_module(f"localization.cli.{argv[0]}")

    def never(_: object) -> None:
        raise AssertionError(f"{argv!r} reached run(): the bad option was not caught")

    monkeypatch.setattr(command, "run", never)
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize(("argv", "option"), BAD, ids=[a for a, _ in BAD])
def test_bad_rerun_option(argv: str, option: str, tmp_path: Path,
                          monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "a_dir").mkdir()
    args = argv.format(file=tmp_path / "a_file", dir=tmp_path / "a_dir").split()
    err = _usage_error(args, monkeypatch, capsys)
    assert f"argument {option}:" in err, err


@pytest.mark.parametrize("command", ["track", "eval --sources oracle", "demo"])
def test_missing_rerun_sdk_names_the_extra(command: str, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "rerun" else real(name, *a))
    err = _usage_error([*command.split(), "--rerun", str(tmp_path / "x.rrd")], monkeypatch,
                       capsys)
    assert "argument --rerun:" in err and "appearance-nav[viewer]" in err, err


def test_eval_writes_a_recording(tmp_path: Path) -> None:
    chunk = pytest.importorskip("rerun.chunk", reason="rerun-sdk is not installed (the viewer "
                                "extra: pip install 'appearance-nav[viewer]')")
    rrd = tmp_path / "eval.rrd"
    proc = _cli("eval", "--agents", "scripted", "--sources", "oracle", "--episodes", "2",
                "--max-episode-steps", "15", "--image-size", "32", "--rerun", str(rrd),
                "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    assert f"rerun {rrd}" in proc.stdout
    entities = {c.entity_path for c in chunk.RrdReader(rrd).stream()}
    run = "scripted/oracle/episode_0"
    assert {f"/map/world/{run}/true", f"/map/world/{run}/path", f"/camera/{run}",
            "/map/world/city/buildings"} <= entities, sorted(entities)
    assert not any("episode_1" in e for e in entities)  # --rerun-episodes 1 by default
