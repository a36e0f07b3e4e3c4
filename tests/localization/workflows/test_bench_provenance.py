"""Benchmark results name what they were measured on (machine, commit, library versions)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from localization.workflows.benchmarks import provenance as prov


def test_provenance_names_the_installed_versions() -> None:
    p = prov.provenance()
    assert set(p) <= {"machine", "python", "git", "versions", "git_at_end"}
    assert {"machine", "python", "git", "versions"} <= set(p)
    assert p["versions"]["numpy"] == np.__version__
    assert set(p["versions"]) == set(prov.LIBRARIES)
    json.dumps(p)  # goes into a result's JSON as it is


def test_a_missing_library_reads_none(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(prov, "LIBRARIES", ("numpy", "no-such-distribution-xyz"))
    versions = prov.library_versions()
    assert versions == {"numpy": np.__version__, "no-such-distribution-xyz": None}


def test_outside_a_checkout_the_commit_is_none(monkeypatch: pytest.MonkeyPatch,
                                               tmp_path) -> None:
    monkeypatch.setattr(prov, "ROOT", tmp_path)  # not a git repository
    assert prov.git_commit() is None


def test_the_commit_is_the_one_the_code_was_loaded_at(monkeypatch: pytest.MonkeyPatch) -> None:
    """A run writes its result at the end; the commit it names is the one it started on."""
    monkeypatch.setattr(prov, "LOADED_COMMIT", "abc1234")
    monkeypatch.setattr(prov, "git_commit", lambda: "def5678")
    p = prov.provenance()
    assert p["git"] == "abc1234" and p["git_at_end"] == "def5678"
    monkeypatch.setattr(prov, "git_commit", lambda: "abc1234")
    assert "git_at_end" not in prov.provenance()
