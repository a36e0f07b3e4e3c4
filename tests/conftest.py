"""Shared by every test: MuJoCo's OpenGL backend is chosen before any test module imports
``mujoco`` (a test file run on its own, ``pytest tests/envs/test_env.py``, imports it before
``envs``; ``make test`` also sets ``MUJOCO_GL``)."""

import envs._gl  # noqa: F401  (sets MUJOCO_GL unless the environment already has it)
