"""The same place under every conditions preset, one image each (the README's figure).

    python -m localization.workflows.conditions_figure docs/img/conditions.png
"""

from __future__ import annotations

import sys
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from envs.conditions import PRESETS

__all__ = ["conditions_figure"]

#: on a street of city 0 looking north past an intersection, driving forward and turning
POSE = (-3.0, -6.5, 1.5708)
STEPS = 8


def preset_images(scene_seed: int = 0, size: int = 128, pose: tuple[float, float, float] = POSE,
                  seed: int = 3) -> dict[str, np.ndarray]:
    """Preset name -> the (size, size, 3) image after ``STEPS`` steps from ``pose``."""
    out = {}
    for name in PRESETS:
        env = gym.make("AppearanceNav-v0", scene_seed=scene_seed, image_size=(size, size),
                       conditions=name)
        obs, _ = env.reset(seed=seed, options={"pose": list(pose)})
        for _ in range(STEPS):
            obs, *_ = env.step([0.8, 0.35])
        out[name] = obs["image"]
        env.close()
    return out


def conditions_figure(path: str | Path, scene_seed: int = 0, size: int = 128) -> Path:
    """Write a grid of :func:`preset_images` to ``path`` (PNG); returns it."""
    images = preset_images(scene_seed, size)
    cols = 5
    rows = -(-len(images) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(2.2 * cols, 2.4 * rows))
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (name, image) in zip(axes.ravel(), images.items()):
        ax.imshow(image)
        ax.set_title(name, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


if __name__ == "__main__":
    print(conditions_figure(sys.argv[1] if len(sys.argv) > 1 else "docs/img/conditions.png"))
