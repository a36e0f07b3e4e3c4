"""The agents row of the global-localization benchmark: the scripted agent on each belief,
kidnapped once per episode (issue 12: ">= 90 % of goals on the particle belief").

Each episode starts on a street lane (:class:`agents.sources.LaneStart`), is kidnapped at step
``kidnap_at`` (:class:`envs.kidnapping.KidnapWrapper` under the belief: no filter is told)
and ends at the goal or after ``max_steps`` steps. The same reset seeds (start, goal, kidnap
pose) run for every filter, on the localizer the benchmark fitted for the city. The EKF runs
with its divergence detection ("ekf_detect") or without it ("ekf"), as in the other rows.
"""

from __future__ import annotations

from typing import Any

from tqdm import tqdm

from agents.evaluation import Episode, run_episodes
from agents.scripted import ScriptedAgent
from agents.sources import make_pose_env

__all__ = ["belief_settings", "kidnapped_episodes"]


def belief_settings(name: str) -> dict[str, Any]:
    """``make_pose_env`` belief keywords of a benchmark filter name."""
    if name == "particles":
        return {"filter": "particles"}
    return {"filter": "ekf", "filter_options": {"detect_divergence": name == "ekf_detect"}}


def kidnapped_episodes(localizer: Any, city: int, names: list[str], episodes: int,
                       seed: int, kidnap_at: int, max_steps: int, image_size: int,
                       motion_noise: float, bar: tqdm | None = None) -> dict[str, list[Episode]]:
    """Per filter name, ``episodes`` scored episodes of the scripted agent (reset seeds
    ``seed .. seed + episodes - 1``), each kidnapped once at step ``kidnap_at``."""
    out: dict[str, list[Episode]] = {}
    for name in names:
        env = make_pose_env("belief", localizer, scene_seed=city,
                            image_size=(image_size, image_size), motion_noise=motion_noise,
                            max_episode_steps=max_steps, kidnap_at=(kidnap_at,),
                            **belief_settings(name))
        agent = ScriptedAgent(env.unwrapped.city)
        out[name] = run_episodes(env, agent, range(seed, seed + episodes), progress=False)
        env.close()
        if bar is not None:
            bar.update()
    return out
