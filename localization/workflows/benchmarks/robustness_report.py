"""Targets and markdown report of the robustness benchmark (:mod:`.robustness`)."""

from __future__ import annotations

from typing import Any

from agents.evaluation import METRIC_COLUMNS, metric_cells
from agents.sources import agent_episode_steps
from envs.conditions import PRESETS
from localization.workflows.benchmarks.appearance_report import map_images_label

__all__ = ["DEFAULT_STEPS", "HELD_OUT_CITIES", "MOVING", "TARGETS", "held_out_label", "markdown", "targets"]

#: the agents' default episode limit in the default 20 m city (400 steps)
DEFAULT_STEPS = agent_episode_steps(20.0)
#: the benchmark's held-out cities: never used to choose anything
HELD_OUT_CITIES = "21,22"

#: issue 17's targets on these rows
TARGETS = {"scripted_nominal": 0.98, "scripted_kidnap_particles": 0.90,
           "scripted_preset": 0.90, "collision_margin": 0.02, "ppo_ratio": 0.97}
BELIEFS = ("ekf", "particles")
#: presets with moving things (the image-free sources run them too: collisions)
MOVING = tuple(name for name, c in PRESETS.items() if c.vehicles or c.pedestrians)


def _target(name: str, value: float, limit: str, ok: bool) -> dict[str, Any]:
    return {"target": name, "value": round(value, 3), "limit": limit, "pass": bool(ok)}


def targets(summary: dict[str, dict[str, float]], moving_localizer: str = "randomised"
            ) -> list[dict[str, Any]]:
    """The issue's targets that the run's rows can decide (rows not run are left out);
    ``moving_localizer`` names the localizer of the presets with moving things."""
    out = []

    def success(key: str) -> float | None:
        return summary[key]["success_rate"] if key in summary else None

    if (v := success("scripted/ekf/nominal")) is not None:
        out.append(_target("scripted on the EKF belief, nominal: success", v,
                           f">= {TARGETS['scripted_nominal']}", v >= TARGETS["scripted_nominal"]))
    if (v := success("scripted/particles/kidnap")) is not None:
        out.append(_target("scripted on the particle belief, one kidnap: success", v,
                           f">= {TARGETS['scripted_kidnap_particles']}",
                           v >= TARGETS["scripted_kidnap_particles"]))
    for preset in PRESETS:
        if (v := success(f"scripted/ekf/{preset}")) is not None:
            training = moving_localizer if preset in MOVING else "randomised"
            out.append(_target(f"scripted on the EKF belief, {preset} ({training} localizer): "
                               "success", v, f">= {TARGETS['scripted_preset']}",
                               v >= TARGETS["scripted_preset"]))
    out += _collision_targets(summary)
    truth, belief = summary.get("ppo/oracle/nominal"), summary.get("ppo/ekf/nominal")
    if truth and belief:
        ratio = belief["success_rate"] / max(truth["success_rate"], 1e-9)
        out.append(_target("PPO success, EKF belief / true pose, nominal", ratio,
                           f">= {TARGETS['ppo_ratio']}", ratio >= TARGETS["ppo_ratio"]))
    return out


def _collision_targets(summary: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
    """Collisions per episode on each belief <= the true pose's + the margin (per agent and
    condition run on both)."""
    out = []
    for key, row in summary.items():
        agent, source, condition = key.split("/")
        truth = summary.get(f"{agent}/oracle/{condition}")
        if source in BELIEFS and truth is not None:
            limit = truth["collisions_per_episode"] + TARGETS["collision_margin"]
            out.append(_target(f"{agent} on {source}, {condition}: collisions per episode"
                               + _traffic_share(row, truth),
                               row["collisions_per_episode"], f"<= {limit:.3f} (true pose + "
                               f"{TARGETS['collision_margin']})",
                               row["collisions_per_episode"] <= limit))
    return out


def _traffic_share(row: dict[str, float], truth: dict[str, float]) -> str:
    """" (with moving objects: belief x, true pose y)" where either touched one."""
    on_row, on_truth = (r.get("traffic_collisions_per_episode", 0.0) for r in (row, truth))
    if not on_row and not on_truth:
        return ""
    return f" (with moving objects: {on_row:.2f}, true pose {on_truth:.2f})"


def success_matrix(result: dict[str, Any]) -> str:
    """Success ± standard error: a row per condition, a column per (agent, source)."""
    summary, conditions = result["summary"], result["args"]["conditions"].split(",")
    limit = result["args"]["max_steps"]
    columns = list(dict.fromkeys(k.rsplit("/", 1)[0] for k in summary))
    lines = ["| condition | " + " | ".join(c.replace("/", " on ") for c in columns) + " |",
             "|---|" + "---:|" * len(columns)]
    for condition in conditions:
        cells = []
        for column in columns:
            row = summary.get(f"{column}/{condition}")
            cells.append("as nominal" if row is None else _success_cell(row, limit))
        lines.append(f"| {condition} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _success_cell(row: dict[str, float], max_steps: int) -> str:
    """"success ± se", and the success within the agents' default episode limit when the
    run's truncation is later."""
    cell = f"{row['success_rate']:.2f} ± {row['success_rate_se']:.2f}"
    if "success_within_default" in row and max_steps > DEFAULT_STEPS:
        cell += f" ({row['success_within_default']:.2f} in {DEFAULT_STEPS})"
    return cell


def metrics_table(result: dict[str, Any]) -> str:
    """Every row with every metric of :func:`agents.evaluation.summarize`."""
    headers = [h for _, h, _ in METRIC_COLUMNS]
    lines = ["| agent | condition | pose source | episodes | " + " | ".join(headers) + " |",
             "|---|---|---|---:|" + "---:|" * len(headers)]
    for key, row in result["summary"].items():
        agent, source, condition = key.split("/")
        lines.append(f"| {agent} | {condition} | {source} | {row['episodes']} | "
                     + " | ".join(metric_cells(row)) + " |")
    return "\n".join(lines)


def tipped_over_note(result: dict[str, Any]) -> str:
    """A line naming the rows in which a moving object flipped the robot over (empty if
    none): those episodes are failures of the env's physics, not of the agent."""
    cells = [f"{key.replace('/', ' / ')}: {row['tipped_over_episodes'] * row['episodes']:.0f} of "
             f"{row['episodes']}" for key, row in result["summary"].items()
             if row.get("tipped_over_episodes", 0.0) > 0]
    return ("\n\nEpisodes in which the robot was flipped on its side or back (it then drives "
            "blind): " + "; ".join(cells) + ".") if cells else ""


def held_out_label(cities: str) -> str:
    """How the report names the cities: held out, or a tuning run on others."""
    held = set(HELD_OUT_CITIES.split(","))
    given = {c.strip() for c in cities.split(",")}
    return "held out" if given <= held else \
        f"not the held-out {HELD_OUT_CITIES}: a run for choosing settings"


_MOVING_ON = {"randomised": "", "daylight": " but traffic, which runs on the daylight one"}
_DAYLIGHT_POSES = {"streets": " around the lanes",
                   "free": " over the whole street surface at every heading"}


def markdown(result: dict[str, Any]) -> str:
    """The report: settings, the success matrix, every metric, the targets."""
    a = result["args"]
    head = (f"# Agents under nominal conditions, kidnapping, appearance presets and moving "
            f"things\n\nCities {a['cities']} ({held_out_label(a['cities'])}), "
            f"{a['image_size']}x{a['image_size']} "
            f"perspective images, motion noise {a['motion_noise']}, {a['episodes']} episodes "
            f"per row and city (reset seeds {a['seed']}..), truncation at {a['max_steps']} "
            f"steps, kidnap (or push: shoved 0.8-1.6 m sideways off the lane) at step "
            f"{a['kidnap_at']}; street-wide localizers: daylight "
            f"({a.get('daylight_features', 'pixel_pca')}, {a['n_train']} images"
            f"{_DAYLIGHT_POSES[a.get('daylight_lanes', 'streets')]}) for nominal, "
            f"kidnap and push, randomised conditions "
            f"({a['randomised_features']}, {a['n_train_randomised']} "
            f"{map_images_label(a.get('randomised_map', 'random'))}) for the presets"
            f"{_MOVING_ON[a.get('moving_localizer', 'randomised')]}; "
            f"{'EKF with divergence detection; ' if a.get('detect_divergence') else ''}"
            f"{result['seconds']:.0f} s ({result['fit_seconds']:.0f} s of fitting, summed "
            "over the workers).\n\n"
            "\"as nominal\": the source never sees an image, so its episodes under a lighting "
            "or camera preset are the nominal ones; \"(x in N)\": the share that reached the "
            "goal within the agents' default N steps.\n\n")
    rows = "\n".join(f"| {t['target']} | {t['value']} | {t['limit']} | "
                     f"{'PASS' if t['pass'] else 'MISS'} |" for t in result["targets"])
    return (head + "## Success\n\n" + success_matrix(result) + "\n\n## Every metric (± standard "
            "error)\n\n" + metrics_table(result) + tipped_over_note(result)
            + "\n\n## Targets\n\n| target | value | limit | status |\n|---|---:|---|---|\n"
            + rows + "\n")
