"""The simulator's names the command line needs (camera, dataset-mode, lane-set and
conditions choices, and PixelPCA's normalisations, which the appearance benchmark offers),
through the workflow layer: the one layer of :mod:`localization` that imports :mod:`envs`.

Importing this module imports :mod:`envs` first, so ``envs._gl`` chooses ``MUJOCO_GL``
before MuJoCo is imported.
"""

from __future__ import annotations

import envs
from envs.conditions import PRESETS
from envs.datasets import MODES
from envs.lanes import LANE_SETS
from envs.scene import check_city_layout
from localization.features.pixel_pca import NORMALIZATIONS

__all__ = ["CAMERAS", "CONDITION_NAMES", "LANE_SETS", "MODES", "NORMALIZATIONS",
           "check_city_layout"]

CAMERAS = envs.CAMERAS
#: the names ``conditions=`` takes: the presets and "random"
CONDITION_NAMES = (*PRESETS, "random")
