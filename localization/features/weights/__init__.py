"""Packaged SmallCNN checkpoints (``torch.load(weights_only=True)``), one per camera and
data regime, each with the JSON record of the command that trained it.

``small_cnn_<camera>_<mode>.pt``: trained by ``scripts/train_small_cnn.py`` on cities
100-119 (never the default evaluation city 0), pose-contrastive objective, on images
collected with ``--mode route`` (the robot driving each city's loop), ``--mode random``
(random 3-DoF poses) or, for "conditions" (perspective only), ``--mode random --conditions
random`` (random poses, every image its own randomised lighting, weather and camera effects:
features meant to carry across appearance change, issue 14). The exact command is in the
``.pt.json`` file next to it.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["MODES", "WEIGHTS_DIR", "small_cnn_weights"]

WEIGHTS_DIR = Path(__file__).resolve().parent
#: data regimes of the packaged checkpoints ("conditions": random poses, every image its own
#: randomised look; perspective only)
MODES = ("route", "random", "conditions")


def small_cnn_weights(camera: str, mode: str = "route") -> Path:
    """Path of the packaged SmallCNN checkpoint for ``camera`` and data ``mode``.

    Raises
    ------
    FileNotFoundError
        Naming the missing file and the command that trains it.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    path = WEIGHTS_DIR / f"small_cnn_{camera}_{mode}.pt"
    if not path.is_file():
        raise FileNotFoundError(
            f"no packaged SmallCNN weights {path.name}; train them with: python "
            f"scripts/train_small_cnn.py --camera {camera} {_mode_options(mode)} "
            f"--num-threads 1 --out {path}")
    return path


def _mode_options(mode: str) -> str:
    """The ``train_small_cnn.py`` options of a packaged data regime."""
    return "--mode random --conditions random" if mode == "conditions" else f"--mode {mode}"
