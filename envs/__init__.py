"""AppearanceNav: a MuJoCo Gymnasium city for appearance-based localization.

Importing :mod:`envs` chooses the offscreen OpenGL backend (``envs._gl``)
before MuJoCo is imported.
"""

from envs import _gl  # noqa: F401  (must run before mujoco is imported)
from envs.motion_model import UnicycleModel, wrap_angle

__all__ = ["UnicycleModel", "wrap_angle"]
