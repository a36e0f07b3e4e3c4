"""Global against heteroscedastic measurement noise (issue 14): the EKF's mean NEES on the
same recorded drives with one R per model, with R(theta) (docs/method.md §15.4), with
R(theta) scaled by the innovations (:mod:`~localization.filtering.adaptive_noise`), and with
one R or R(theta) and a persistent bias state (:mod:`~localization.filtering.measurement_bias`,
§15.6).

    appearance-nav bench --only noise --noise-cities 31,32 --noise-n-drives 4
    # 345 s wall at load 3.9-4.7 (2 cores, shared); the table is in docs/benchmarks.md §8

On each city a daylight localizer with the appearance benchmark's earlier settings
(:mod:`.appearance` has since moved to 15000 images, PixelPCA(128, normalize="patches") and
GSE's forward terms; those terms tried here cost consistency, docs/benchmarks.md §8) is
fitted (:func:`~localization.workflows.tracking.fit_city_localizer` around the route's
lanes, 64 x 64 images, 6000 of them, PixelPCA(64, normalize="channels"), motion noise 0.1, a
1500-step noise drive), with ``noise_folds=5``: the K-fold residuals that the heteroscedastic
scale is learned from (the global R still comes from the noise drive, as without them).
Then ``n_drives`` drives of ``drive_steps`` steps (around the route from path points 0,
600, ...; or street tours with ``lanes="streets"``) are recorded on the true pose under each
condition preset, and the "representation" belief runs
over each five times, from the first image (psi*), as :data:`FILTERS` says
(``noise="global"``, ``noise="heteroscedastic"``, the latter with ``adaptive_noise=True``,
and each with ``measurement_bias=True``): the same images, controls and start for all. Reported per city
and condition: position RMSE and the mean over drives of the run-averaged NEES against its
chi-square 95 % band (:func:`~localization.workflows.tracking.nees_band`), for each.
"""

from __future__ import annotations

import dataclasses
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import numpy as np

from envs.datasets import drive_route, drive_streets
from localization.filtering.belief import BeliefFilter
from localization.geometry import pose_residual
from localization.workflows.benchmarks.provenance import provenance
from localization.workflows.tracking import fit_city_localizer, nees_band

__all__ = ["FILTERS", "NoiseBenchConfig", "plot_nees", "run_noise_bench", "target_counts"]

#: the compared beliefs: their BeliefFilter noise options
FILTERS: dict[str, dict[str, Any]] = {
    "global": {"noise": "global"},
    "heteroscedastic": {"noise": "heteroscedastic"},
    "adaptive": {"noise": "heteroscedastic", "adaptive_noise": True},
    "bias": {"noise": "global", "measurement_bias": True},
    "hetero_bias": {"noise": "heteroscedastic", "measurement_bias": True},
}
#: their names in the figure
LABELS = {"global": "global R", "heteroscedastic": "R(θ, w)",
          "adaptive": "R(θ, w) scaled by the innovations",
          "bias": "global R with a persistent bias",
          "hetero_bias": "R(θ, w) with a persistent bias"}


@dataclass
class NoiseBenchConfig:
    """Settings of the noise-model comparison."""

    cities: str = field(default="31,32", metadata={"help": "comma-separated scene seeds"})
    conditions: str = field(default="default,overcast,fog,seasonal,exposure,noise,motion_blur,"
                                    "traffic",
                            metadata={"help": "condition presets of the recorded drives (the "
                                              "localizer sees daylight only)"})
    lanes: str = field(default="route", metadata={"help": "route or streets"})
    n_train: int = field(default=6000, metadata={"help": "lane training images"})
    image_size: int = field(default=64, metadata={"help": "square image side (px)"})
    n_components: int = field(default=64, metadata={"help": "PixelPCA components"})
    normalize: str = field(default="channels", metadata={"help": "PixelPCA normalize"})
    n_drive: int = field(default=1500, metadata={"help": "steps of the noise drive"})
    n_drives: int = field(default=4, metadata={"help": "recorded drives per city and condition"})
    drive_steps: int = field(default=300, metadata={"help": "steps of each recorded drive"})
    motion_noise: float = field(default=0.1, metadata={"help": "env actuation noise"})
    noise_folds: int = field(default=5, metadata={
        "help": "K-fold refits of the heteroscedastic scale (3 split city 12's graph)"})
    first_order: str = field(default="frames", metadata={
        "help": "the first-order terms of GSE's r*: frames or forward (docs/method.md "
                "section 8.5)"})
    forward_ridge: float = field(default=0.03, metadata={
        "help": "first_order=forward: GSERegressor(forward_ridge=...) (the appearance "
                "benchmark's 0.03)"})
    seed: int = field(default=0, metadata={"help": "seed of the fit and the drives"})
    out_dir: str = field(default="results", metadata={
        "help": "where bench_noise.json/.md go"})


def make_env(args: NoiseBenchConfig, city: int, conditions: str = "default") -> gym.Env:
    return gym.make("AppearanceNav-v0", scene_seed=city, conditions=conditions,
                    image_size=(args.image_size, args.image_size),
                    motion_noise=args.motion_noise, max_episode_steps=None)


def fit(args: NoiseBenchConfig, city: int) -> Any:
    """The street-wide localizer of ``city`` with its K-fold heteroscedastic scales."""
    env = make_env(args, city)
    params: dict[str, Any] = {"n_components": args.n_components}
    if args.normalize != "none":
        params["normalize"] = args.normalize
    with warnings.catch_warnings():  # GSE's eigen-gap warning, the quality warning
        warnings.simplefilter("ignore")
        loc, _ = fit_city_localizer(
            env, n_train=args.n_train, lanes=args.lanes, n_drive=args.n_drive, seed=args.seed,
            localizer_params={"noise_folds": args.noise_folds, "features_params": params,
                              "regressor_params": regressor_params(args)},
            calibrate_on_belief=False, measurements=("representation",), quality_steps=0)
    env.close()
    return loc


def regressor_params(args: NoiseBenchConfig) -> dict[str, Any]:
    """The GSERegressor settings: ``first_order``, and ``forward_ridge`` with "forward"."""
    if args.first_order == "forward":
        return {"first_order": "forward", "forward_ridge": args.forward_ridge}
    return {"first_order": args.first_order}


def record(env: gym.Env, args: NoiseBenchConfig, k: int) -> tuple[np.ndarray, ...]:
    """Drive ``k`` on the true pose: (images, poses, controls)."""
    seed = args.seed + 1000 * (k + 1)
    if args.lanes == "route":
        return drive_route(env, args.drive_steps, seed=seed, start=600 * k, progress=False)
    return drive_streets(env, args.drive_steps, seed=seed, progress=False)


def score_drive(loc: Any, motion_model: Any, W: np.ndarray, poses: np.ndarray,
                controls: np.ndarray, options: dict[str, Any]) -> dict[str, float]:
    """The belief (BeliefFilter ``options``) over one recorded drive from its first image:
    RMSE, mean NEES, acceptance."""
    belief = BeliefFilter(loc, motion_model, "representation", **options)
    means, covs, status = belief.run(W, controls)
    e = np.array([pose_residual(t, m) for t, m in zip(poses, means)])
    nees = np.einsum("ni,nij,nj->n", e, np.linalg.inv(covs), e)
    return {"rmse": float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
            "nees_mean": float(np.mean(nees)),
            "accepted": float(np.mean(np.array(status[1:]) == "accepted"))}


def summarize(runs: list[dict[str, float]]) -> dict[str, Any]:
    lo, hi = nees_band(len(runs))
    nees = float(np.mean([r["nees_mean"] for r in runs]))
    return {"drives": len(runs), "nees_mean": nees, "nees_band": [lo, hi],
            "in_band": bool(lo <= nees <= hi),
            "rmse": float(np.sqrt(np.mean([r["rmse"] ** 2 for r in runs]))),
            "accepted": float(np.mean([r["accepted"] for r in runs]))}


def run_noise_bench(args: NoiseBenchConfig) -> dict[str, Any]:
    """Run the comparison; write ``bench_noise.json`` / ``.md`` to ``out_dir``; return it."""
    t0 = time.perf_counter()
    cities = [int(c) for c in args.cities.split(",")]
    conditions = [c.strip() for c in args.conditions.split(",")]
    runs: dict[str, dict[str, list[dict[str, float]]]] = {}
    for city in cities:
        loc = fit(args, city)
        for cond in conditions:
            env = make_env(args, city, cond)
            key = f"{city}/{cond}"
            runs[key] = {n: [] for n in FILTERS}
            for k in range(args.n_drives):
                images, poses, controls = record(env, args, k)
                W = loc.transform(images)
                for n, options in FILTERS.items():
                    runs[key][n].append(score_drive(loc, env.unwrapped.motion_model, W, poses,
                                                    controls, options))
            env.close()
    summary = {key: {n: summarize(r[n]) for n in FILTERS} for key, r in runs.items()}
    result = {"args": dataclasses.asdict(args), **provenance(), "seconds": time.perf_counter() - t0,
              "summary": summary, "runs": runs}
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_noise.json").write_text(json.dumps(result, indent=2))
    (out / "bench_noise.md").write_text(markdown(result) + "\n")
    plot_nees(result, out / "bench_noise.png")
    print(markdown(result))
    return result


def filters_of(result: dict[str, Any]) -> list[str]:
    """The beliefs of :data:`FILTERS` that every group of the run has, in that order."""
    return [n for n in FILTERS if all(n in s for s in result["summary"].values())]


def plot_nees(result: dict[str, Any], path: str | Path) -> Path:
    """A PNG of the run: per city and condition, each belief's mean NEES against the
    chi-square 95 % band (shaded; log scale) and its position RMSE."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(result["summary"])
    names = filters_of(result)
    y = np.arange(len(groups))
    height = 0.8 / len(names)
    fig, (ax_nees, ax_rmse) = plt.subplots(1, 2, figsize=(10, 0.35 * len(groups) + 1.5),
                                           sharey=True)
    lo, hi = result["summary"][groups[0]][names[0]]["nees_band"]
    ax_nees.axvspan(lo, hi, color="0.9", label="95 % band")
    for i, n in enumerate(names):
        offset = y + (i - (len(names) - 1) / 2) * height
        s = [result["summary"][g][n] for g in groups]
        ax_nees.barh(offset, [r["nees_mean"] for r in s], height, label=LABELS[n])
        ax_rmse.barh(offset, [r["rmse"] for r in s], height)
    ax_nees.set_xscale("log")
    ax_nees.set_xlabel("mean NEES (3 dof)")
    ax_rmse.set_xlabel("position RMSE (m)")
    ax_nees.set_yticks(y, groups)
    ax_nees.invert_yaxis()
    fig.legend(*ax_nees.get_legend_handles_labels(), loc="upper center", ncol=4, fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.5 / fig.get_figheight()))
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def target_counts(result: dict[str, Any]) -> dict[str, dict[str, int]]:
    """Per belief, the issue's target read two ways: groups (city, condition: the mean NEES
    of its drives) and single drives (each drive's run-averaged NEES against the band of
    one value) in the band, and how many of the global belief's out-of-band ones are inside."""
    lo, hi = nees_band(1)
    summary, runs = result["summary"], result["runs"]
    groups_out = [g for g, s in summary.items() if not s["global"]["in_band"]]
    drives_out = [(g, i) for g, r in runs.items() for i, d in enumerate(r["global"])
                  if not lo <= d["nees_mean"] <= hi]

    def inside(n: str, g: str, i: int) -> bool:
        return bool(lo <= runs[g][n][i]["nees_mean"] <= hi)

    return {n: {"groups": len(summary), "groups_in_band": sum(s[n]["in_band"]
                                                              for s in summary.values()),
                "global_out_groups": len(groups_out),
                "global_out_groups_inside": sum(summary[g][n]["in_band"] for g in groups_out),
                "drives": sum(len(r[n]) for r in runs.values()),
                "drives_in_band": sum(inside(n, g, i) for g, r in runs.items()
                                      for i in range(len(r[n]))),
                "global_out_drives": len(drives_out),
                "global_out_drives_inside": sum(inside(n, g, i) for g, i in drives_out)}
            for n in filters_of(result)}


def markdown(result: dict[str, Any]) -> str:
    """A table: per city and condition, RMSE and mean NEES (band) of each belief of the
    run (those of :data:`FILTERS` it has); then :func:`target_counts`."""
    names = filters_of(result)
    lines = ["| city / condition | NEES band | "
             + " | ".join(f"{n}: RMSE, NEES" for n in names) + " |",
             "|---|---|" + "---|" * len(names)]
    for key, s in result["summary"].items():
        lo, hi = s["global"]["nees_band"]
        cell = [f"{r['rmse']:.3f} m, {r['nees_mean']:.2f}{'' if r['in_band'] else ' (out)'}"
                for r in (s[n] for n in names)]
        lines.append(f"| {key} | [{lo:.2f}, {hi:.2f}] | " + " | ".join(cell) + " |")
    if "runs" not in result:  # a summary only: no drives to count
        return "\n".join(lines)
    lo, hi = nees_band(1)
    head = ("| belief | groups in band | of the global's out-of-band groups, inside | "
            f"drives in band [{lo:.2f}, {hi:.2f}] | of the global's out-of-band drives, inside |")
    lines += ["", head, "|---|---|---|---|---|"]
    for n, c in target_counts(result).items():
        lines.append(f"| {n} | {c['groups_in_band']} / {c['groups']} | "
                     f"{c['global_out_groups_inside']} / {c['global_out_groups']} | "
                     f"{c['drives_in_band']} / {c['drives']} | "
                     f"{c['global_out_drives_inside']} / {c['global_out_drives']} |")
    return "\n".join(lines)
