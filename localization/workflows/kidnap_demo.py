"""The demo's kidnapping stage: one unannounced kidnap, the EKF and the particle belief side
by side on the same recorded drive, and a figure of it.

The robot drives a street tour, is teleported (:class:`envs.kidnapping.KidnapWrapper`, the
filters are not told) and drives on (:func:`~localization.workflows.kidnap_eval.record_kidnap_drive`).
The figure shows the particles over the map at four instants (before the kidnap, just after,
while re-localizing, at the end; red = heavy) with the true pose (cyan ring), and the position error over time of both
filters with the kidnap marked.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from localization.filtering.particles import ParticleBelief
from localization.geometry import Array
from localization.workflows.kidnap_eval import (
    KidnapDrive,
    record_kidnap_drive,
    run_filter,
    steps_to_recover,
)

__all__ = ["kidnap_demo", "plot_kidnap"]

P0 = np.diag([0.01, 0.01, 0.001])
LABELS = {"ekf": "EKF without detection", "ekf_detect": "EKF (divergence detection)",
          "particles": "particles"}


def _particle_run(localizer: Any, motion_model: Any, drive: KidnapDrive, snapshots: list[int],
                  seed: int) -> tuple[Array, dict[int, tuple[Array, Array]]]:
    """Dominant-mode means (n + 1, 3) and the particles and weights at ``snapshots``."""
    pf = ParticleBelief(localizer, motion_model, seed=seed)
    pf.reset(drive.W[0], x0=drive.poses[0], P0=P0)
    means, shots = [pf.pose_mean], {}
    for t, (u, w) in enumerate(zip(drive.controls, drive.W[1:]), start=1):
        pf.step(u, w)
        means.append(pf.pose_mean)
        if t in snapshots:
            shots[t] = (pf.particles.copy(), pf.weights.copy())
    return np.asarray(means), shots


def plot_kidnap(top_down: Array, bounds: tuple[float, float], drive: KidnapDrive,
                errors: dict[str, Array], shots: dict[int, tuple[Array, Array]],
                path: str | Path) -> Path:
    """Particles over the map at the snapshot steps (top) and the error of each filter over
    time with the kidnap marked (bottom); saved as a PNG at ``path``."""
    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(2, len(shots), height_ratios=[1.3, 1.0])
    lo, hi = bounds
    for i, (t, (X, w)) in enumerate(sorted(shots.items())):
        ax = fig.add_subplot(grid[0, i])
        ax.imshow(top_down, extent=(lo, hi, lo, hi), origin="upper")
        ax.plot(*drive.poses[t, :2], "o", ms=14, mfc="none", mec="cyan", mew=2)  # true pose
        order = np.argsort(w)  # heaviest particles drawn last
        ax.scatter(X[order, 0], X[order, 1], s=4, c=w[order], cmap="autumn_r", zorder=3)
        ax.set_title(f"step {t}" + (" (kidnap)" if t == drive.kidnap else ""))
        ax.set_xticks([])
        ax.set_yticks([])
    ax = fig.add_subplot(grid[1, :])
    for name, e in errors.items():
        ax.semilogy(np.maximum(e, 1e-3), label=name)
    if drive.kidnap is not None:
        ax.axvline(drive.kidnap, color="k", ls="--", label="kidnap")
    ax.axhline(0.5, color="gray", lw=0.8)
    ax.set_xlabel("step (0.1 s)")
    ax.set_ylabel("position error (m)")
    ax.legend(loc="upper right")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def kidnap_demo(env: gym.Env, localizer: Any, out: str | Path, seed: int = 0,
                steps_before: int = 100, steps_after: int = 150) -> dict[str, Any]:
    """Record one kidnap drive on ``env`` and replay it through the EKF without divergence
    detection ("ekf", ``BeliefWrapper``'s default), with it ("ekf_detect") and the particle
    belief; write ``<out>/kidnap.png``; return the steps each filter took to recover (None:
    not within the drive) and the figure's path."""
    drive = record_kidnap_drive(env, localizer, steps_before, steps_after, seed=seed)
    k = drive.kidnap if drive.kidnap is not None else steps_before
    snapshots = [k - 1, k + 2, k + 8, len(drive.controls)]
    motion = env.unwrapped.motion_model
    means = {name: run_filter(name, drive, localizer, motion)[0]
             for name in ("ekf", "ekf_detect")}
    means["particles"], shots = _particle_run(localizer, motion, drive, snapshots, seed)
    errors = {LABELS[name]: np.hypot(*(m[:, :2] - drive.poses[:, :2]).T)
              for name, m in means.items()}
    env.unwrapped.set_pose(drive.poses[-1])
    png = plot_kidnap(env.unwrapped.render(), env.unwrapped.city.bounds, drive, errors, shots,
                      Path(out) / "kidnap.png")
    return {"kidnap_step": k, "png": str(png),
            "steps_to_recover": {name: steps_to_recover(m, drive.poses, k)
                                 for name, m in means.items()},
            "rmse_before": {name: float(np.sqrt(np.mean(e[:k] ** 2)))
                            for name, e in errors.items()}}
