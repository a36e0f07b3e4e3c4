"""The one place that chooses MuJoCo's offscreen OpenGL backend.

``MUJOCO_GL`` must be set before ``mujoco`` is first imported, so :mod:`envs`
imports this module first. A value already in the environment wins; otherwise
EGL (Mesa, works headless out of the box) is used. ``python -m envs._gl``
probes which backend renders here and prints it; ``make`` uses that to fall
back to OSMesa (apt package ``libosmesa6``) only when EGL cannot render.
"""

from __future__ import annotations

import os
import subprocess
import sys

DEFAULT_BACKEND = "egl"
FALLBACK_BACKEND = "osmesa"

os.environ.setdefault("MUJOCO_GL", DEFAULT_BACKEND)

_PROBE = (
    "import mujoco; m = mujoco.MjModel.from_xml_string('<mujoco/>'); "
    "r = mujoco.Renderer(m, 8, 8); d = mujoco.MjData(m); r.update_scene(d); "
    "r.render(); r.close()"
)


def can_render(backend: str) -> bool:
    """Return whether MuJoCo renders offscreen with ``backend`` (in a subprocess)."""
    env = dict(os.environ, MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend)
    proc = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                          check=False)
    return proc.returncode == 0


def main() -> int:
    for backend in (DEFAULT_BACKEND, FALLBACK_BACKEND):
        if can_render(backend):
            print(backend)
            return 0
    print("neither EGL nor OSMesa can render; install libosmesa6", file=sys.stderr)
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
