"""AppearanceNav: a MuJoCo Gymnasium city for appearance-based localization.

Importing :mod:`envs` chooses the offscreen OpenGL backend (``envs._gl``)
before MuJoCo is imported, and registers ``AppearanceNav-v0``.
"""

from envs import _gl  # noqa: F401  (must run before mujoco is imported)

# isort: split
import gymnasium as gym

from envs.appearance_nav import AppearanceNavEnv
from envs.cameras import CAMERAS, make_camera, register_camera
from envs.datasets import collect_dataset, load_dataset, save_dataset
from envs.kidnapping import KIDNAP_RATE_PER_METRE, KidnapWrapper
from envs.motion_model import UnicycleModel, wrap_angle
from envs.scene import City, generate_city
from envs.time_limit import CityTimeLimit, episode_steps

if "AppearanceNav-v0" not in gym.registry:
    # no fixed max_episode_steps: CityTimeLimit truncates after episode_steps(city_size)
    # (500 for the default 20 m city); max_episode_steps=N still gives gymnasium's TimeLimit(N)
    gym.register(
        id="AppearanceNav-v0",
        entry_point="envs.appearance_nav:make_appearance_nav",
        additional_wrappers=(CityTimeLimit.wrapper_spec(),),
    )

__all__ = [
    "CAMERAS",
    "KIDNAP_RATE_PER_METRE",
    "AppearanceNavEnv",
    "City",
    "CityTimeLimit",
    "KidnapWrapper",
    "UnicycleModel",
    "collect_dataset",
    "episode_steps",
    "generate_city",
    "load_dataset",
    "make_camera",
    "register_camera",
    "save_dataset",
    "wrap_angle",
]
