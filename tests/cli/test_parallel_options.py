"""``--workers`` and ``--ray-address`` of ``collect`` and ``eval``: bad values are usage
errors naming the option, before any work."""

from __future__ import annotations

import importlib
import sys

import pytest

from localization.cli import main

BAD = [
    ("collect --workers 0", "--workers", "positive"),
    ("collect --workers -3", "--workers", "positive"),
    ("collect --ray-address nowhere", "--ray-address", "ray://host:port"),
    ("eval --agents scripted --sources oracle --workers 0", "--workers", "positive"),
    ("eval --agents scripted --sources oracle --ray-address ray://x", "--ray-address", "host"),
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
    return capsys.readouterr().err.split("error: ", 1)[1]


@pytest.mark.parametrize(("argv", "option", "says"), BAD, ids=[a for a, _, _ in BAD])
def test_bad_parallel_option_is_a_usage_error(argv: str, option: str, says: str,
                                              monkeypatch: pytest.MonkeyPatch,
                                              capsys: pytest.CaptureFixture) -> None:
    message = _usage_error(argv.split(), monkeypatch, capsys)
    assert message.startswith(f"argument {option}:") and says in message, message


@pytest.mark.parametrize("command", ["collect", "eval --agents scripted --sources oracle"])
def test_ray_address_without_ray_names_the_extra(command: str, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # find_spec("ray") -> None: not installed
    message = _usage_error([*command.split(), "--ray-address", "auto"], monkeypatch, capsys)
    assert message.startswith("argument --ray-address:") and "[distributed]" in message, message


def test_eval_rerun_needs_one_worker(tmp_path: object, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip("rerun")
    argv = f"eval --agents scripted --sources oracle --workers 2 --rerun {tmp_path}/e.rrd"
    message = _usage_error(argv.split(), monkeypatch, capsys)
    assert message.startswith("argument --rerun:") and "--workers 1" in message, message
