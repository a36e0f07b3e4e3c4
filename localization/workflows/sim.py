"""The simulator's names the command line needs (camera, dataset-mode and lane-set choices),
through the workflow layer: the one layer of :mod:`localization` that imports :mod:`envs`.

Importing this module imports :mod:`envs` first, so ``envs._gl`` chooses ``MUJOCO_GL``
before MuJoCo is imported.
"""

from __future__ import annotations

import envs
from envs.datasets import MODES
from envs.lanes import LANE_SETS

__all__ = ["CAMERAS", "LANE_SETS", "MODES"]

CAMERAS = envs.CAMERAS
