"""The ``--rerun FILE.rrd`` option of ``track``, ``eval`` and ``demo``: checked before any work."""

from __future__ import annotations

import importlib.util

from localization.cli._args import UsageError, check_output_file
from localization.workflows.rerun_log import VIEWER_EXTRA

__all__ = ["check_rerun"]


def check_rerun(path: str, option: str = "rerun") -> None:
    """``path`` is empty (no recording) or a writable ``.rrd`` file path, and rerun-sdk is
    installed (else a :class:`UsageError` naming the extra to install)."""
    if not path:
        return
    check_output_file(option, path, suffixes=(".rrd",))
    if importlib.util.find_spec("rerun") is None:
        raise UsageError(option, f"Rerun recordings need rerun-sdk, which is not installed: "
                                 f"{VIEWER_EXTRA}")
