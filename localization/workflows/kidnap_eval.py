"""Kidnapped-robot and global-localization evaluation of the pose beliefs (issue 12).

Protocol (the robot keeps driving the streets on its true pose, so every filter sees the
same images and controls):

1. :func:`record_kidnap_drive`: from a random intersection the robot drives a random street
   tour (:class:`envs.datasets.PurePursuit` on the true pose) for ``steps_before`` steps;
   :class:`envs.kidnapping.KidnapWrapper` then teleports it (at least ``min_distance`` m,
   unannounced) and it drives a new tour from there for ``steps_after`` steps.
2. :func:`run_filter` replays the drive through a filter that starts at the true start pose:
   "ekf" (:class:`~localization.filtering.belief.BeliefFilter` as it was, waiting for 50
   steps without an accepted measurement), "ekf_detect" (the same with its divergence
   detection, :mod:`localization.filtering.divergence`) or "particles"
   (:class:`~localization.filtering.particles.ParticleBelief`).
3. :func:`steps_to_recover`: steps from the kidnap until the position error stays below
   ``RECOVERED_ERROR`` (0.5 m) for ``RECOVERED_STEPS`` (10) steps in a row (the first of
   them); None if it never does within the drive.

:func:`evaluate_global` starts the particle filter with no pose (``reset(mode="global")``).
The benchmark (:mod:`localization.workflows.benchmarks.global_loc`) runs all of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from envs.datasets import PurePursuit
from envs.kidnapping import KidnapWrapper
from envs.lanes import street_tour
from localization.filtering.belief import BeliefFilter
from localization.filtering.free_space import city_sampler
from localization.filtering.particles import ParticleBelief
from localization.geometry import Array

__all__ = ["KidnapDrive", "evaluate_global", "record_kidnap_drive", "run_filter", "steps_to_recover"]

RECOVERED_ERROR = 0.5  # m
RECOVERED_STEPS = 10
FILTERS = ("ekf", "ekf_detect", "particles")


@dataclass
class KidnapDrive:
    """A recorded drive: features ``W`` (n + 1, m), true ``poses`` (n + 1, 3), ``controls``
    (n, 2); ``kidnap`` = the frame index of the first image after the kidnap (or None)."""

    W: Array
    poses: Array
    controls: Array
    kidnap: int | None


def tour_from(city: Any, pose: Array, length: float, rng: np.random.Generator) -> Array:
    """Waypoints (p, 2) of a random street tour starting at ``pose``: to the intersection
    ahead (the nearest within 60 degrees of the heading), then on as
    :func:`envs.lanes.street_tour` (no U-turns) for ``length`` metres."""
    nodes, edges = city.street_graph()
    d = nodes - pose[:2]
    ahead = d @ np.array([np.cos(pose[2]), np.sin(pose[2])]) > 0.5 * np.hypot(*d.T)
    dist = np.where(ahead, np.hypot(*d.T), np.inf)
    node = int(np.argmin(dist)) if np.isfinite(dist).any() else int(np.argmin(np.hypot(*d.T)))
    neighbours: dict[int, list[int]] = {i: [] for i in range(len(nodes))}
    for i, j in edges:
        neighbours[i].append(j)
        neighbours[j].append(i)
    heading = np.array([np.cos(pose[2]), np.sin(pose[2])])
    behind = min(neighbours[node], key=lambda j: float((nodes[j] - nodes[node]) @ heading))
    prev, tour, total = behind, [pose[:2], nodes[node]], 0.0
    while total < length:
        options = [j for j in neighbours[node] if j != prev] or neighbours[node]
        prev, node = node, options[int(rng.integers(len(options)))]
        total += float(np.hypot(*(nodes[node] - nodes[prev])))
        tour.append(nodes[node])
    return np.asarray(tour, dtype=np.float64)


def record_kidnap_drive(env: gym.Env, localizer: Any, steps_before: int, steps_after: int,
                        seed: int, min_distance: float = 5.0, speed: float = 0.6) -> KidnapDrive:
    """Drive, get kidnapped after ``steps_before`` steps, drive on (see the module docstring).
    ``steps_after=0``: no kidnap."""
    base = env.unwrapped
    rng = np.random.default_rng(seed)
    n = steps_before + steps_after
    length = 1.5 * n * base.dt * speed + 10.0
    pilot = PurePursuit(street_tour(base.city, length, rng), speed=speed, w_max=base.W_MAX,
                        closed=False)
    at = (steps_before + 1,) if steps_after > 0 else ()
    kid = KidnapWrapper(env, at_steps=at, min_distance=min_distance, seed=seed)
    obs, info = kid.reset(seed=seed, options={"pose": pilot.start_pose(0)})
    images, poses, controls = [obs["image"]], [info["pose"]], []
    kidnap = None
    for t in range(n):
        u = pilot(poses[-1])  # on the kidnap step: the old plan's control, at the new place
        obs, _, _, _, info = kid.step(u)
        if info["kidnapped"]:
            kidnap = t + 1
            pilot = PurePursuit(tour_from(base.city, info["pose"], length, rng), speed=speed,
                                w_max=base.W_MAX, closed=False)
        images.append(obs["image"])
        poses.append(info["pose"])
        controls.append(u)
    W = localizer.transform(np.asarray(images))
    return KidnapDrive(W, np.asarray(poses), np.asarray(controls, dtype=np.float64), kidnap)


def run_filter(name: str, drive: KidnapDrive, localizer: Any, motion_model: Any,
               seed: int = 0, hypotheses: list[dict[str, Array]] | None = None,
               **options: Any) -> tuple[Array, Array, list[str]]:
    """Replay ``drive`` through filter ``name`` (one of ``FILTERS``) started at the true
    start pose; ``options`` go to its constructor. Returns means, covs and the belief's
    statuses ("tracking", "ambiguous", "relocalizing", "lost", ...: what the wrapper reports
    as ``info["belief_status"]``; for the EKF not its measurement statuses). A list passed
    as ``hypotheses`` receives each frame's hypotheses ("weights" (k,), "means" (k, 3));
    the EKF has one, its own mean."""
    if name not in FILTERS:
        raise ValueError(f"unknown filter {name!r}; choose one of {FILTERS}")
    P0 = np.diag([0.01, 0.01, 0.001])
    if name not in ("ekf", "ekf_detect"):
        f = ParticleBelief(localizer, motion_model, seed=seed, **options)
        return f.run(drive.W, drive.controls, x0=drive.poses[0], P0=P0, hypotheses=hypotheses)
    options = {"detect_divergence": name == "ekf_detect", **options}
    ekf = BeliefFilter(localizer, motion_model, **options)
    ekf.reset(drive.W[0], drive.poses[0], P0)
    means, covs, statuses = [ekf.x], [ekf.P], [ekf.belief_status]
    for u, w in zip(drive.controls, drive.W[1:]):
        ekf.step(u, w)
        means.append(ekf.x)
        covs.append(ekf.P)
        statuses.append(ekf.belief_status)
    if hypotheses is not None:
        hypotheses += [{"weights": np.ones(1), "means": m[None]} for m in means]
    return np.array(means), np.array(covs), statuses


def steps_to_recover(means: Array, poses: Array, start: int) -> int | None:
    """Steps from frame ``start`` to the first of ``RECOVERED_STEPS`` frames in a row with
    a position error below ``RECOVERED_ERROR``; None if none within the drive."""
    ok = np.hypot(*(means[start:, :2] - poses[start:, :2]).T) < RECOVERED_ERROR
    run = np.convolve(ok.astype(int), np.ones(RECOVERED_STEPS, int), "valid")
    hits = np.flatnonzero(run == RECOVERED_STEPS)
    return int(hits[0]) if len(hits) else None


def _summary(steps: list[int | None], within: int) -> dict[str, float]:
    s = np.array([np.inf if k is None else k for k in steps], dtype=float)
    return {"n": len(s), f"recovered_within_{within}": float(np.mean(s <= within)),
            "recovered": float(np.mean(np.isfinite(s))), "median_steps": float(np.median(s)),
            "p95_steps": float(np.percentile(s, 95, method="higher"))}  # inf: not recovered


def evaluate_global(env: gym.Env, localizer: Any, n_starts: int = 20, steps: int = 60,
                    seed: int = 0, within: int = 30, **options: Any) -> dict[str, Any]:
    """Global localization: the particle filter starts with ``reset(mode="global")``
    (proposals + the street sampler) on ``n_starts`` drives; steps to localize as
    :func:`steps_to_recover` from frame 0."""
    mm = env.unwrapped.motion_model
    found = []
    for k in range(n_starts):
        drive = record_kidnap_drive(env, localizer, steps, 0, seed + k)
        f = ParticleBelief(localizer, mm, seed=seed + k,
                           sample_free=city_sampler(env.unwrapped.city), **options)
        means, _, _ = f.run(drive.W, drive.controls, mode="global")
        found.append(steps_to_recover(means, drive.poses, 0))
    return {"steps": found, **_summary(found, within)}

