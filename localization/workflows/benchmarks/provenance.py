"""What a benchmark result was measured on: the machine, the commit and the libraries.

The project's dependencies are lower bounds (``pyproject.toml``), so a fresh environment
may bring newer numpy, scipy or MuJoCo than the last run had. A closed loop on a marginal
map can move with them (docs/benchmarks.md §9, stop 66: the randomised map's default drive
read 0.187 m in one environment and 0.247 m on the same code in another), so every result
names its versions.
"""

from __future__ import annotations

import importlib.metadata
import platform
import subprocess
from pathlib import Path
from typing import Any

__all__ = ["LIBRARIES", "LOADED_COMMIT", "ROOT", "provenance"]

#: the distributions whose versions a result records
LIBRARIES = ("numpy", "scipy", "scikit-learn", "mujoco", "gymnasium", "torch", "filterpy",
             "pyamg", "stable-baselines3")

#: the repository (its git commit is the code's; the GSE benchmark's workers run there)
ROOT = Path(__file__).resolve().parents[3]


def library_versions() -> dict[str, str | None]:
    """Installed version of each of :data:`LIBRARIES` (None when it is not installed)."""
    out: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out


def git_commit() -> str | None:
    """The repository's short HEAD commit, with ``+dirty`` for uncommitted changes (None
    outside a git checkout)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, check=True,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=ROOT, check=True, capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty else "") if head else None


#: the commit when this module was first imported, i.e. when a benchmark's code was loaded
#: (a result is written at the end of its run, and HEAD may have moved on meanwhile)
LOADED_COMMIT = git_commit()


def provenance() -> dict[str, Any]:
    """``{"machine", "python", "git", "versions"}`` of this run, for a result's JSON.
    ``git`` is the commit whose code the process loaded (:data:`LOADED_COMMIT`); when the
    checkout has moved since, ``git_at_end`` names the commit at the time of the call."""
    out = {"machine": platform.platform(), "python": platform.python_version(),
           "git": LOADED_COMMIT, "versions": library_versions()}
    now = git_commit()
    if now != LOADED_COMMIT:
        out["git_at_end"] = now
    return out
