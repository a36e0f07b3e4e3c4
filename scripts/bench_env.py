"""Benchmark of AppearanceNav-v0: env steps/s vs a raw MuJoCo step+render loop.

CleanRL style: one file, every setting in ``Args`` (``--help`` lists them), results in files.

    python scripts/bench_env.py                 # perspective camera, 64/96/128 px
    python scripts/bench_env.py --cameras       # every registered camera
    python scripts/bench_env.py --quick         # smoke run

What is measured
----------------
* env: ``gymnasium.make("AppearanceNav-v0", ...)`` (with gymnasium's default wrappers)
  stepped by a random policy (``action_space.sample()``), resetting at episode ends.
* raw: the same compiled scene (``env.unwrapped.model``) with a fresh ``MjData``: random
  wheel-speed commands, ``mj_step(model, data, frame_skip)`` and one camera image per step;
  for "perspective" through a bare ``mujoco.Renderer(model, H, W)`` on camera "ego", for
  the other cameras through the same camera class the env uses (``make_camera``).
* ratio = env / raw. env and raw runs alternate in ``rounds`` rounds and each number is the
  median over rounds, so load from other processes hits both alike.
Targets (PASS/MISS): >= 1000 env steps/s at 64x64 (perspective) and ratio >= 0.8.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import envs  # noqa: E402  (chooses MUJOCO_GL before mujoco is imported)
import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from envs.cameras import make_camera  # noqa: E402

TARGET_STEPS_PER_S = 1000.0
TARGET_RATIO = 0.8


@dataclass
class Args:
    sizes: str = field(default="64,96,128", metadata={"help": "comma-separated square image sides"})
    steps: int = field(default=1000, metadata={"help": "steps per timed run"})
    rounds: int = field(default=5, metadata={"help": "alternating env/raw rounds; medians are reported"})
    warmup: int = field(default=50, metadata={"help": "untimed steps before each run"})
    scene_seed: int = field(default=0, metadata={"help": "city of the benchmark"})
    seed: int = field(default=0, metadata={"help": "seed of the random policy"})
    cameras: bool = field(default=False, metadata={"help": "loop over every registered camera, not just perspective"})
    quick: bool = field(default=False, metadata={"help": "smoke run: 64 px, 200 steps, 2 rounds"})
    out_dir: str = field(default="results", metadata={"help": "where bench_env.json / bench_env.md go"})


def parse_args(argv: list[str] | None = None) -> Args:
    """Parse ``--field-name value`` options (booleans are flags) from the fields of ``Args``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    for f in dataclasses.fields(Args):
        name = "--" + f.name.replace("_", "-")
        if isinstance(f.default, bool):
            parser.add_argument(name, action="store_true", help=f.metadata["help"])
        else:
            parser.add_argument(name, type=type(f.default), default=f.default,
                                help=f"{f.metadata['help']} (default: {f.default!r})")
    args = Args(**vars(parser.parse_args(argv)))
    if args.quick:
        args.sizes, args.steps, args.rounds, args.warmup = "64", 200, 2, 10
    return args


def time_env(env: gym.Env, steps: int, warmup: int) -> float:
    """Random-policy env steps per second."""
    env.reset(seed=0)
    for i in range(warmup + steps):
        if i == warmup:
            t0 = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - t0)


class RawLoop:
    """mj_step(frame_skip) + one camera image per step on the env's compiled scene."""

    def __init__(self, env: gym.Env, camera: str, size: int, seed: int) -> None:
        base = env.unwrapped
        self.model, self.frame_skip = base.model, base.frame_skip
        self.data = mujoco.MjData(self.model)
        self.rng = np.random.default_rng(seed)
        x, y, yaw = base.city.random_free_pose(self.rng, 0.4)
        self.data.qpos[:7] = [x, y, 0.05, np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]
        mujoco.mj_forward(self.model, self.data)
        if camera == "perspective":
            self.renderer = mujoco.Renderer(self.model, size, size)
            self.render = self._render_bare
        else:
            self.camera = make_camera(camera, self.model, (size, size))
            self.render = lambda: self.camera.render(self.data)

    def _render_bare(self) -> np.ndarray:
        self.renderer.update_scene(self.data, camera="ego")
        return self.renderer.render()

    def run(self, steps: int, warmup: int) -> float:
        """Steps per second."""
        lo, hi = self.model.actuator_ctrlrange[:, 0] / 2, self.model.actuator_ctrlrange[:, 1] / 2
        for i in range(warmup + steps):
            if i == warmup:
                t0 = time.perf_counter()
            self.data.ctrl[:] = self.rng.uniform(lo, hi)
            mujoco.mj_step(self.model, self.data, self.frame_skip)
            self.render()
        return steps / (time.perf_counter() - t0)

    def close(self) -> None:
        if hasattr(self, "renderer"):
            self.renderer.close()
        else:
            self.camera.close()


def bench_one(camera: str, size: int, args: Args) -> dict[str, Any]:
    env = gym.make("AppearanceNav-v0", scene_seed=args.scene_seed, camera=camera, image_size=(size, size),
                   max_episode_steps=500)
    env.action_space.seed(args.seed)
    raw = RawLoop(env, camera, size, args.seed)
    env_runs, raw_runs = [], []
    for _ in range(args.rounds):
        env_runs.append(time_env(env, args.steps, args.warmup))
        raw_runs.append(raw.run(args.steps, args.warmup))
    raw.close()
    env.close()
    env_sps, raw_sps = float(np.median(env_runs)), float(np.median(raw_runs))
    return {"camera": camera, "size": size, "env_steps_per_s": env_sps, "raw_steps_per_s": raw_sps,
            "ratio": env_sps / raw_sps, "env_runs": env_runs, "raw_runs": raw_runs}


def gl_renderer() -> str:
    try:
        from OpenGL import GL

        r = mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 16, 16)
        name = GL.glGetString(GL.GL_RENDERER).decode()
        r.close()
        return name
    except Exception as err:  # informative only
        return f"unknown ({err})"


def markdown(rows: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    lines = [
        "# AppearanceNav-v0 step throughput",
        "",
        f"Random policy, dt = {meta['dt']} s ({meta['frame_skip']} physics steps), {meta['steps']} steps x "
        f"{meta['rounds']} alternating rounds (median). GL: {meta['gl_renderer']}, MUJOCO_GL={meta['mujoco_gl']}, "
        f"{meta['cpu_count']} CPUs, load average at start {meta['loadavg']}.",
        "",
        "| camera | image | env steps/s | raw step+render/s | env/raw | >= 1000/s | >= 0.8x |",
        "|---|---|---:|---:|---:|---|---|",
    ]
    for r in rows:
        fast = "PASS" if r["env_steps_per_s"] >= TARGET_STEPS_PER_S else "MISS"
        close = "PASS" if r["ratio"] >= TARGET_RATIO else "MISS"
        if not (r["camera"] == "perspective" and r["size"] == 64):
            fast = f"({fast})"  # the target is stated for 64x64 perspective only
        lines.append(f"| {r['camera']} | {r['size']}x{r['size']} | {r['env_steps_per_s']:.0f} | "
                     f"{r['raw_steps_per_s']:.0f} | {r['ratio']:.2f} | {fast} | {close} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    args = parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    cameras = sorted(envs.CAMERAS) if args.cameras else ["perspective"]
    probe = envs.AppearanceNavEnv(scene_seed=args.scene_seed)
    meta = {"args": dataclasses.asdict(args), "dt": probe.dt, "frame_skip": probe.frame_skip,
            "steps": args.steps, "rounds": args.rounds, "gl_renderer": gl_renderer(),
            "mujoco_gl": os.environ.get("MUJOCO_GL"), "mujoco": mujoco.__version__,
            "python": platform.python_version(), "cpu_count": os.cpu_count(),
            "loadavg": [round(v, 2) for v in os.getloadavg()]}
    probe.close()
    rows = []
    for camera in cameras:
        for size in sizes:
            rows.append(bench_one(camera, size, args))
            r = rows[-1]
            print(f"{camera:>13s} {size:4d}px  env {r['env_steps_per_s']:7.0f}/s  raw {r['raw_steps_per_s']:7.0f}/s"
                  f"  ratio {r['ratio']:.2f}", flush=True)
    table = markdown(rows, meta)
    print("\n" + table)
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_env.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    (out / "bench_env.md").write_text(table)
    return rows


if __name__ == "__main__":
    main()
