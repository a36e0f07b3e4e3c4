"""One loop for filtering a recorded sequence with either belief (``BeliefFilter.run``,
``ParticleBelief.run``): frames 0..n of features and the n controls between them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from localization.geometry import Array

__all__ = ["run_recorded"]


def run_recorded(belief: Any, W: ArrayLike, controls: ArrayLike, start: Callable[[Array], str],
                 record: Callable[[], None] | None = None) -> tuple[Array, Array, list[str]]:
    """``start(W[0])``, then ``belief.step(u, w)`` for each control and next frame; the
    belief's ``x`` and ``P`` after each (``record()`` too, if given).

    Returns
    -------
    means : (n + 1, 3)
    covs : (n + 1, 3, 3)
    statuses : list of n + 1 str

    Raises
    ------
    ValueError
        Unless ``W`` is (n + 1, m) and ``controls`` (n, 2).
    """
    W, controls = np.asarray(W, dtype=np.float64), np.asarray(controls, dtype=np.float64)
    if W.ndim != 2 or controls.shape != (len(W) - 1, 2):
        raise ValueError(f"need W (n + 1, m) and controls (n, 2), got {W.shape} and "
                         f"{controls.shape}")
    statuses, means, covs = [], [], []

    def keep(status: str) -> None:
        statuses.append(status)
        means.append(belief.x)
        covs.append(belief.P)
        if record is not None:
            record()

    keep(start(W[0]))
    for u, w in zip(controls, W[1:]):
        keep(belief.step(u, w)[1])
    return np.array(means), np.array(covs), statuses
