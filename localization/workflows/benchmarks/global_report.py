"""The markdown table of the global-localization benchmark
(:mod:`localization.workflows.benchmarks.global_loc`): rows = measures, columns = filters."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["markdown"]


def _pct(v: float) -> str:
    return "n/a" if v is None or not np.isfinite(v) else f"{100 * v:.0f} %"


def _num(v: float, fmt: str = ".1f") -> str:
    return "n/a" if v is None else ("inf" if v == np.inf else format(v, fmt))


def _mark(ok: bool | None) -> str:
    return "" if ok is None else (" PASS" if ok else " MISS")


def markdown(result: dict[str, Any]) -> str:
    """The side-by-side table of ``result`` (rows = measures, columns = filters)."""
    s, names = result["summary"], result["filters"]
    ekf_rmse = s["ekf"]["nominal"]["rmse"] if "ekf" in s else None
    rows: list[tuple[str, str, list[str]]] = []

    def row(label: str, target: str, cell: Any) -> None:
        rows.append((label, target, [cell(s[n], n) for n in names]))

    k = lambda f: f["kidnap"]
    row(f"kidnap: recovered within 30 steps (n = {s[names[0]]['kidnap']['n']})", ">= 95 %",
        lambda f, n: _pct(k(f)["recovered_within_30"]) + _mark(k(f)["recovered_within_30"] >= 0.95))
    row("kidnap: median / p95 steps to recover", "median <= 10",
        lambda f, n: f"{_num(k(f)['median_steps'], '.0f')} / {_num(k(f)['p95_steps'], '.0f')}"
        + _mark(k(f)["median_steps"] <= 10))
    row("kidnap: while lost (> 1 m), status lost or truth in 3-sigma", ">= 90 %",
        lambda f, n: f"{_pct(k(f)['admitted_while_lost'])} of {k(f)['lost_steps']}"
        + _mark(None if not k(f)["lost_steps"] else k(f)["admitted_while_lost"] >= 0.9))
    row("global start: localized within 30 steps", ">= 95 %",
        lambda f, n: "n/a" if f["global"] is None else
        f"{_pct(f['global']['recovered_within_30'])} of {f['global']['n']}"
        + _mark(f["global"]["recovered_within_30"] >= 0.95))
    look = lambda f: f["lookalike"]
    row(f"look-alike city {result['args']['lookalike_city']}: runs committed to a wrong twin "
        "> 20 steps (its report there, its status tracking)", "<= 5 %",
        lambda f, n: f"{_pct(look(f)['wrong_twin_runs'])} of {look(f)['n']}"
        + _mark(look(f)["wrong_twin_runs"] <= 0.05))
    row("look-alike city: runs reported on a wrong twin > 20 steps, any status", "",
        lambda f, n: f"{_pct(look(f)['twin_report_runs'])} of {look(f)['n']}")
    row("look-alike city: frames reported on a wrong twin that keep a hypothesis at the "
        "truth", "", lambda f, n: f"{_pct(look(f)['twin_kept'])} of {look(f)['twin_frames']}")
    row("look-alike city: recovered within 30 steps", "",
        lambda f, n: _pct(f["lookalike"]["recovered_within_30"]))
    row("nominal: position RMSE (m)", "<= 1.2 x EKF",
        lambda f, n: f"{f['nominal']['rmse']:.3f}" + ("" if ekf_rmse is None or n == "ekf" else
                                                      _mark(f["nominal"]["rmse"] <= 1.2 * ekf_rmse)))
    row("nominal: mean NEES (3 dof)", "in band",
        lambda f, n: f"{f['nominal']['nees_mean']:.2f} [{f['nominal']['nees_band'][0]:.2f}, "
        f"{f['nominal']['nees_band'][1]:.2f}]" + _mark(
            f["nominal"]["nees_band"][0] <= f["nominal"]["nees_mean"] <= f["nominal"]["nees_band"][1]))
    row("cost: ms per step (one core)", "<= 20",
        lambda f, n: f"{f['nominal']['ms_per_step']:.1f}" + _mark(f["nominal"]["ms_per_step"] <= 20))
    row("agents: scripted agent, one kidnap per episode: success", ">= 90 % (particles)",
        lambda f, n: "n/a" if f.get("agents") is None else
        f"{_pct(f['agents']['success_rate'])} ± {_pct(f['agents']['success_rate_se'])} of "
        f"{f['agents']['episodes']}" + ("" if n != "particles" else
                                         _mark(f["agents"]["success_rate"] >= 0.9)))
    lines = [f"Global localization ({result['setup']}):", "",
             "| measure | target | " + " | ".join(names) + " |",
             "|---|---|" + "---:|" * len(names)]
    lines += [f"| {label} | {target} | " + " | ".join(cells) + " |" for label, target, cells in rows]
    return "\n".join(lines) + "\n"
