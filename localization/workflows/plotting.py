"""Figures of the workflows (matplotlib, Agg backend): a driven route, a closed-loop
tracking run.

:func:`plot_route` writes the city map with a driven route and a strip of camera images
along it (``appearance-nav demo``).

:func:`plot_track` writes one PNG per run: the top-down city map with the true path, the
belief path with 2-sigma covariance ellipses and the dead-reckoning path (F alone from the
true start pose); the position error over time (belief, its 2-sigma bound, dead reckoning);
the NEES and NIS over time with their chi-square 95 % bands per step.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Ellipse
from scipy.stats import chi2

from localization.workflows.tracking import TrackResult, track_metrics

__all__ = ["COLORS", "covariance_ellipse", "plot_route", "plot_track"]

COLORS = {"true": "black", "belief": "tab:red", "dead_reckoning": "tab:blue"}


def covariance_ellipse(mean: np.ndarray, cov: np.ndarray, n_sigma: float = 2.0,
                       **kw: Any) -> Ellipse:
    """The ``n_sigma`` ellipse of a 2-D Gaussian (position block of a pose covariance)."""
    vals, vecs = np.linalg.eigh(cov)
    angle = np.degrees(np.arctan2(vecs[1, 1], vecs[0, 1]))
    w, h = 2.0 * n_sigma * np.sqrt(np.maximum(vals[::-1], 0.0))
    return Ellipse(tuple(mean), w, h, angle=angle, **kw)


def plot_track(run: TrackResult, top_down: np.ndarray, bounds: tuple[float, float],
               path: str | Path, title: str = "", ellipse_every: int = 25) -> Path:
    """Write the figure of one run to ``path`` (PNG); returns the path.

    Parameters
    ----------
    run : TrackResult
    top_down : (H, W, 3) uint8
        The env's top-down map (``env.render()``), north up.
    bounds : (lo, hi)
        City bounds in metres (the map's extent on both axes).
    path : output file.
    title : str
    ellipse_every : int
        Steps between drawn covariance ellipses.
    """
    m = track_metrics(run)
    t = np.arange(len(run.true))
    fig = plt.figure(figsize=(13, 6.5))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.0, 1.25])
    ax = fig.add_subplot(grid[:, 0])
    lo, hi = bounds
    ax.imshow(top_down, extent=(lo, hi, lo, hi))
    ax.plot(*run.dead_reckoning[:, :2].T, "-", color=COLORS["dead_reckoning"], lw=1.2,
            label=f"dead reckoning (RMSE {m['rmse_dead_reckoning']:.2f} m)")
    ax.plot(*run.true[:, :2].T, "-", color=COLORS["true"], lw=1.6, label="true")
    ax.plot(*run.mean[:, :2].T, "--", color=COLORS["belief"], lw=1.2,
            label=f"belief (RMSE {m['rmse']:.3f} m)")
    for i in range(0, len(t), ellipse_every):
        ax.add_patch(covariance_ellipse(run.mean[i, :2], run.cov[i, :2, :2], fill=False,
                                        color=COLORS["belief"], lw=0.8))
    ax.plot(*run.true[0, :2], "o", color="lime", ms=7, label="start")
    margin = 1.0
    ax.set_xlim(lo - margin, hi + margin)
    ax.set_ylim(lo - margin, hi + margin)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="lower left", fontsize=7, framealpha=0.85)
    ax.set_title(f"{run.measurement}: belief with 2-sigma ellipses", fontsize=10)

    err = np.hypot(*(run.mean[:, :2] - run.true[:, :2]).T)
    dr = np.hypot(*(run.dead_reckoning[:, :2] - run.true[:, :2]).T)
    bound = 2.0 * np.sqrt(run.cov[:, 0, 0] + run.cov[:, 1, 1])
    a1 = fig.add_subplot(grid[0, 1])
    a1.plot(t, dr, color=COLORS["dead_reckoning"], lw=1, label="dead reckoning")
    a1.plot(t, err, color=COLORS["belief"], lw=1, label="belief")
    a1.fill_between(t, 0, bound, color=COLORS["belief"], alpha=0.15, label="belief 2-sigma")
    a1.set_yscale("log")
    a1.set_ylim(1e-3, max(10.0, float(dr.max()) * 1.5))
    a1.set_ylabel("position error (m)")
    a1.legend(fontsize=7, loc="upper left", ncol=3)

    a2 = fig.add_subplot(grid[1, 1], sharex=a1)
    lo3, hi3 = chi2.ppf([0.025, 0.975], 3)
    a2.plot(t, run.nees, color="tab:purple", lw=0.8, label=f"NEES (mean {m['nees_mean']:.2f})")
    a2.axhspan(lo3, hi3, color="tab:green", alpha=0.12, label="chi2(3) 95 %")
    a2.axhline(3.0, color="tab:green", lw=0.8)
    a2.set_yscale("log")
    a2.set_ylabel("NEES")
    a2.legend(fontsize=7, loc="upper left", ncol=2)

    a3 = fig.add_subplot(grid[2, 1], sharex=a1)
    status = np.array(run.status)
    ok = status == "accepted"
    a3.plot(t[ok], run.nis[ok], ".", ms=2, color="tab:gray", label="NIS (accepted)")
    rej = np.isin(status, ("gated", "out_of_domain", "relocalized", "reverted"))
    a3.plot(t[rej], np.where(np.isfinite(run.nis[rej]), run.nis[rej], 1e3), "x", ms=3,
            color="tab:orange", label=f"rejected ({rej.sum()})")
    lo_d, hi_d = chi2.ppf([0.025, 0.975], run.nis_dof)
    a3.axhspan(lo_d, hi_d, color="tab:green", alpha=0.12, label=f"chi2({run.nis_dof}) 95 %")
    a3.set_yscale("log")
    a3.set_ylabel("NIS")
    a3.set_xlabel("step")
    a3.legend(fontsize=7, loc="upper left", ncol=3)
    fig.suptitle(title or f"{run.measurement}: {m['steps']} steps, RMSE {m['rmse']:.3f} m vs "
                 f"dead reckoning {m['rmse_dead_reckoning']:.2f} m", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_route(env: Any, images: np.ndarray, poses: np.ndarray, n_strip: int,
               path: str | Path) -> Path:
    """Top-down map with the driven route and the frames of the strip marked, plus the strip.

    Parameters
    ----------
    env : an ``AppearanceNav-v0`` env (its city map is rendered top-down).
    images : (n, H, W, 3) uint8 camera images along the route.
    poses : (n, 3) poses ``[x, y, yaw]`` of the images.
    n_strip : camera images shown below the map (evenly spaced along the route).
    path : the PNG written.

    Returns
    -------
    ``path`` as a :class:`~pathlib.Path`.
    """
    path = Path(path)
    base = env.unwrapped
    lo, hi = base.city.bounds
    top = base.render()
    picks = np.linspace(0, len(poses) - 1, n_strip).round().astype(int)
    fig = plt.figure(figsize=(2.0 * n_strip, 2.0 * n_strip / 2 + 2.4))
    grid = fig.add_gridspec(2, n_strip, height_ratios=[n_strip / 2, 1])
    ax = fig.add_subplot(grid[0, :])
    ax.imshow(top, extent=(lo, hi, lo, hi))
    ax.plot(poses[:, 0], poses[:, 1], "-", color="tab:orange", lw=1.5, label="driven route")
    for k, i in enumerate(picks):
        x, y, yaw = poses[i]
        ax.annotate("", (x + 0.8 * np.cos(yaw), y + 0.8 * np.sin(yaw)), (x, y),
                    arrowprops={"arrowstyle": "->", "color": "tab:cyan", "lw": 1.5})
        ax.text(x, y, f" {k + 1}", color="white", fontsize=9, weight="bold")
    ax.set_title(f"city {base.city.seed}: {len(poses)} frames along the route "
                 f"({np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T)):.0f} m)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="upper right", fontsize=8)
    for k, i in enumerate(picks):
        a = fig.add_subplot(grid[1, k])
        a.imshow(images[i])
        a.set_title(f"{k + 1}: ({poses[i, 0]:.1f}, {poses[i, 1]:.1f}, "
                    f"{np.degrees(poses[i, 2]):.0f}°)", fontsize=7)
        a.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
