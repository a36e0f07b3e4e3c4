"""The markdown tables of the coverage benchmark (:mod:`.coverage`), with the issue's targets
marked PASS / MISS."""

from __future__ import annotations

from typing import Any

__all__ = ["THRESHOLDS", "markdown"]

#: (metres, degrees) of the visual-localization benchmarks (Aachen Day-Night)
THRESHOLDS = ((0.25, 2.0), (0.5, 5.0), (5.0, 10.0))
#: issue 13's targets for GSE
MEDIAN_TARGET, WITHIN_TARGET = 0.15, (0.75, 0.90)
RMSE_TARGET, RATIO_TARGET = 0.15, 0.05


def _mark(ok: bool) -> str:
    return " PASS" if ok else " MISS"


def _single_row(camera: str, method: str, s: dict[str, Any], others: list[dict[str, Any]]
                ) -> str:
    cells = " / ".join(f"{100 * v:.1f}" for v in s["within"])
    median = f"{s['median_pos_err']:.3f}"
    if method.startswith("GSE"):
        ok = all(v >= t for v, t in zip(s["within"], WITHIN_TARGET))
        cells += f"{_mark(ok)} (>= 75 / 90)"
        median += _mark(s["median_pos_err"] <= MEDIAN_TARGET)
        ahead = all(s["within"][1] > o["within"][1] and s["median_pos_err"] < o["median_pos_err"]
                    for o in others)
        median += f", ahead{_mark(ahead)}"
    return (f"| {camera} | {method} | {cells} | {median} | {s['median_yaw_err_deg']:.2f} | "
            f"{100 * s['out_of_domain']:.1f} % |")


def _loop_row(camera: str, training: str, s: dict[str, Any], target: bool) -> str:
    lo, hi = s["nees_band"]
    rmse, ratio = f"{s['rmse']:.3f}", f"{s['ratio']:.3f}"
    nees = f"{s['nees_mean']:.2f} [{lo:.2f}, {hi:.2f}]"
    if target:
        rmse += _mark(s["rmse"] <= RMSE_TARGET)
        ratio += _mark(s["ratio"] <= RATIO_TARGET)
        nees += _mark(lo <= s["nees_mean"] <= hi)
    return (f"| {camera} | {training} | {s['drives']} | {rmse} | {s['rmse_dead_reckoning']:.3f} "
            f"| {ratio} | {s['max_error']:.2f} | {nees} | {100 * s['accepted']:.0f} % |")


def markdown(result: dict[str, Any]) -> str:
    """Two tables: single images per (camera, method); off-lane drives per (camera, training)."""
    lines = [f"Localization anywhere on the streets at any heading ({result['setup']}):", "",
             ("| camera | method | % within (0.25 m, 2°) / (0.5 m, 5°) / (5 m, 10°) | "
              "median position error (m; target <= 0.15) | median heading error (°) | "
              "outside the domain |"),
             "|---|---|---|---|---:|---:|"]
    for camera in result["cameras"]:
        single = result["summary"][camera]["single"]
        for method, s in single.items():
            others = [o for m, o in single.items() if not m.startswith("GSE")]
            lines.append(_single_row(camera, method, s, others))
    lines += ["", ("| camera | training | off-lane drives | belief RMSE (m; <= 0.15) | dead "
                   "reckoning RMSE (m) | ratio (<= 0.05) | largest error (m) | mean NEES "
                   "[95 % band] | measurements accepted |"),
              "|---|---|---:|---|---:|---|---:|---|---:|"]
    for camera in result["cameras"]:
        for training, s in result["summary"][camera]["closed_loop"].items():
            lines.append(_loop_row(camera, training, s, training == "coverage"))
    for failure in result.get("fit_failures", []):
        lines += ["", f"Fit failed: {failure}"]
    return "\n".join(lines) + "\n"
