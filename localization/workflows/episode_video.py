"""The demo's episode video: the scripted agent on the particle belief through a kidnap.

:func:`episode_video` drives one episode of :class:`~agents.scripted.ScriptedAgent` on
:class:`~localization.wrappers.BeliefWrapper` (``filter="particles"``) from a lane pose to the
farthest street intersection, with one unannounced kidnap
(:class:`envs.kidnapping.KidnapWrapper`), and writes every ``render()`` frame (the belief on
the map, the camera image, the status) to an MP4 with imageio-ffmpeg; optionally the same
episode to a Rerun recording (:mod:`localization.workflows.rerun_log`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
from PIL import Image

from agents.scripted import ScriptedAgent
from envs.datasets import PurePursuit
from envs.kidnapping import KidnapWrapper
from localization.workflows.kidnap_eval import steps_to_recover
from localization.workflows.rerun_log import RerunLog, RerunRecorder
from localization.wrappers import BeliefWrapper

__all__ = ["episode_video"]


class _Mp4:
    """Frames to an H.264 MP4 as they come (no frame is kept in memory)."""

    def __init__(self, path: Path, fps: float) -> None:
        self.writer = imageio.get_writer(path, format="FFMPEG", mode="I", fps=fps,
                                         codec="libx264", quality=7, pixelformat="yuv420p",
                                         macro_block_size=16, ffmpeg_log_level="error")
        self.frames = 0

    def append(self, frame: np.ndarray) -> None:
        self.writer.append_data(frame)
        self.frames += 1

    def close(self) -> None:
        self.writer.close()


def _start_and_goal(city: Any) -> tuple[np.ndarray, np.ndarray]:
    """The route's first pose and the inner street intersection farthest from it (at the
    city's border the camera looks out of the city)."""
    start = PurePursuit(city.route()).start_pose(0)
    nodes, _ = city.street_graph()
    edge = np.abs(city.street_centers).max()
    inner = nodes[np.all(np.abs(nodes) < edge, axis=1)]
    inner = inner if len(inner) else nodes
    return start, inner[np.argmax(np.hypot(*(inner - start[:2]).T))]


def episode_video(localizer: Any, out: str | Path, *, scene_seed: int = 0,
                  camera: str = "perspective", image_size: int = 64,
                  motion_noise: float = 0.1, seed: int = 0, kidnap_at: int = 60,
                  max_steps: int = 400, rerun: str | Path | None = None) -> dict[str, Any]:
    """Drive the episode (see the module docstring); write ``out`` (MP4) and, with suffix
    ``.png``, the first frame after the kidnap whose belief is not "tracking" (the filter
    has noticed; else the last frame); return a summary.

    Returns
    -------
    dict with ``mp4``, ``png``, ``frames``, ``steps``, ``success`` (goal reached),
    ``kidnap_step``, ``steps_to_recover`` (particle belief within 1 m again; None if not
    within the episode), ``seconds``, ``ms_per_frame`` (render + encode) and ``rerun``.
    """
    t0 = time.perf_counter()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    env = gym.make("AppearanceNav-v0", scene_seed=scene_seed, camera=camera,
                   image_size=(image_size, image_size), motion_noise=motion_noise,
                   max_episode_steps=max_steps, render_mode="rgb_array")
    kidnapped = KidnapWrapper(env, at_steps=(kidnap_at,), seed=seed)
    belief = BeliefWrapper(kidnapped, localizer, filter="particles", filter_options={"seed": seed})
    log = None if rerun is None else RerunLog(rerun, env.unwrapped.top_down_map())
    driven = belief if log is None else RerunRecorder(belief, log, "demo/scripted_particles")
    agent = ScriptedAgent(env.unwrapped.city)
    start, goal = _start_and_goal(env.unwrapped.city)
    obs, info = driven.reset(seed=seed, options={"pose": start, "goal": goal})
    agent.reset()
    writer = _Mp4(out, env.metadata.get("render_fps", 10))
    true, mean, draw_seconds, still = [info["pose"]], [belief.mean], 0.0, None
    done, success = False, False
    try:
        while True:
            t = time.perf_counter()
            frame = driven.render()
            writer.append(frame)
            draw_seconds += time.perf_counter() - t
            if (still is None and len(true) > kidnap_at
                    and info.get("belief_status") != "tracking"):
                still = frame  # the belief has noticed the kidnap: the particles at work
            if done:
                break
            action = agent.act(obs, info)
            belief.planned_path = agent.path
            obs, _, terminated, truncated, info = driven.step(action)
            true.append(info["pose"])
            mean.append(belief.mean)
            done, success = terminated or truncated, bool(terminated)
    finally:
        writer.close()
        env.close()
        if log is not None:
            log.close()
    png = out.with_suffix(".png")
    Image.fromarray(still if still is not None else frame).save(png)
    true_a, mean_a = np.asarray(true), np.asarray(mean)
    recovered = (steps_to_recover(mean_a, true_a, kidnap_at) if len(true) > kidnap_at
                 else None)
    return {"mp4": str(out), "png": str(png), "frames": writer.frames, "steps": len(true) - 1,
            "success": success, "kidnap_step": kidnap_at, "steps_to_recover": recovered,
            "seconds": round(time.perf_counter() - t0, 1),
            "ms_per_frame": round(1e3 * draw_seconds / max(writer.frames, 1), 2),
            "rerun": None if rerun is None else str(rerun)}
