"""The ``--workers`` and ``--ray-address`` options of ``collect`` and ``eval``: checked before
any work."""

from __future__ import annotations

import importlib.util
from typing import Any

from localization.cli._args import UsageError
from localization.workflows.parallel import DISTRIBUTED_EXTRA, check_ray_address, check_workers

__all__ = ["check_parallel"]


def check_parallel(args: Any) -> None:
    """``args.workers`` is a positive integer, and ``args.ray_address`` is empty or a Ray
    address with Ray installed (else a :class:`UsageError` naming the extra to install)."""
    try:
        check_workers(args.workers)
    except (TypeError, ValueError) as err:
        raise UsageError("workers", str(err).split(" ", 1)[1]) from None
    try:
        address = check_ray_address(args.ray_address)
    except (TypeError, ValueError) as err:
        raise UsageError("ray_address", str(err).split(" ", 1)[1]) from None
    if address and importlib.util.find_spec("ray") is None:
        raise UsageError("ray_address", f"Ray is not installed: {DISTRIBUTED_EXTRA}")
