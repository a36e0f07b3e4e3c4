"""Train a PPO navigator (stable-baselines3 ``MultiInputPolicy``) on a pose source
(``appearance-nav train``).

The policy sees :class:`agents.observations.NavigationObservation` (the street plan and goal
in the belief's body frame, plus the belief's standard deviations), never the true pose; it is
rewarded for progress along the street path (:class:`agents.rewards.StreetProgressReward`).
Writes to ``<out>/<pose_source>/``: ``policy.pt`` + ``policy.json`` (loadable without pickle by
``agents.ppo.PPOAgent.load``), ``checkpoints/``, ``progress.csv`` (training log),
``evaluations.npz`` (``EvalCallback``: returns, lengths and success rates on held-out resets)
and ``train.json`` (settings, timing, final evaluation).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import envs  # noqa: F401  (chooses MUJOCO_GL before mujoco is imported)

# isort: split
import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, EvalCallback
from stable_baselines3.common.logger import configure
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv
from tqdm import tqdm

from agents.observations import NavigationObservation
from agents.ppo import make_ppo, save_policy
from agents.rewards import StreetProgressReward
from agents.sources import POSE_SOURCES, make_pose_env
from localization.loading import load_localizer
from localization.localizer import AppearanceLocalizer
from localization.workflows.agent_env import AgentEnvSettings, city_options

__all__ = ["VEC_ENVS", "PolicyCheckpoint", "ProgressBar", "TrainConfig", "make_vec_env",
           "train_agent"]

VEC_ENVS = ("subproc", "dummy")


@dataclass
class TrainConfig(AgentEnvSettings):
    """Settings of a training run (the options of ``appearance-nav train``)."""

    pose_source: str = field(default="belief", metadata={
        "help": "what the policy navigates on: " + ", ".join(POSE_SOURCES)})
    total_timesteps: int = field(default=300_000, metadata={"help": "PPO environment steps"})
    n_envs: int = field(default=8, metadata={"help": "environments per rollout"})
    vec_env: str = field(default="subproc", metadata={
        "help": "'subproc' (the envs step in forked worker processes: all cores render and "
                "filter) or 'dummy' (one process)"})
    n_steps: int = field(default=256, metadata={"help": "rollout steps per environment"})
    batch_size: int = field(default=512, metadata={"help": "PPO minibatch size"})
    seed: int = field(default=0, metadata={"help": "seed of PPO and of the training resets"})
    eval_freq: int = field(default=25_000, metadata={
        "help": "environment steps between evaluations"})
    eval_episodes: int = field(default=20, metadata={"help": "episodes per evaluation"})
    checkpoint_freq: int = field(default=100_000, metadata={"help": "steps between checkpoints"})
    threads: int = field(default=1, metadata={"help": "torch threads"})
    out: str = field(default="results/agents", metadata={"help": "output folder"})
    progress: bool = field(default=True, metadata={"help": "show a progress bar"})
    status: bool = field(default=False, metadata={
        "help": "the policy also sees the belief status (tracking, ambiguous, doubtful, lost, "
                "relocalizing) one-hot"})
    bumper: bool = field(default=False, metadata={
        "help": "the policy also feels the bump sensor (info['collision'] and where it was "
                "touched, with a few steps' memory: agents.observations)"})
    kidnap_at: str = field(default="", metadata={
        "help": "comma-separated steps of each training episode that start with a kidnap "
                "(empty: none)"})
    conditions: str = field(default="", metadata={
        "help": "look of the training episodes (envs.conditions: a preset such as 'night', or "
                "'random'; empty: the default look)"})
    filter: str = field(default="ekf", metadata={"help": "the belief's filter: ekf or particles"})
    detect_divergence: bool = field(default=False, metadata={
        "help": "EKF: notice when lost and restart where the images agree (method 13.1)"})
    uncertainty_penalty: float = field(default=0.0, metadata={
        "help": "active localization: reward weight of the belief's position entropy above "
                "0.1 m (agents.rewards; 0: off)"})

    def kidnap_steps(self) -> tuple[int, ...]:
        """``kidnap_at`` as a tuple of step numbers."""
        try:
            steps = tuple(int(v) for v in self.kidnap_at.split(",") if v.strip())
        except ValueError:
            raise ValueError(f"kidnap_at must be comma-separated step numbers, got "
                             f"{self.kidnap_at!r}") from None
        if any(k < 0 for k in steps):
            raise ValueError(f"kidnap_at steps must be >= 0, got {self.kidnap_at!r}")
        return steps

    def source_options(self) -> dict[str, object]:
        """``make_pose_env`` keywords of the kidnaps, conditions and (belief only) filter."""
        options: dict[str, object] = {"kidnap_at": self.kidnap_steps(),
                                      "conditions": self.conditions or None}
        if self.pose_source == "belief":
            options["filter"] = self.filter
            if self.detect_divergence:
                options["filter_options"] = {"detect_divergence": True}
        elif self.filter != "ekf" or self.detect_divergence:
            raise ValueError("filter and detect_divergence apply to pose_source 'belief' only")
        return options


class ProgressBar(BaseCallback):
    """A tqdm bar over the training steps, with the latest mean episode return."""

    def __init__(self, total: int, enabled: bool) -> None:
        super().__init__()
        self.bar = tqdm(total=total, desc="ppo", unit="step", disable=not enabled)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        if self.model.ep_info_buffer:
            self.bar.set_postfix(ret=f"{np.mean([e['r'] for e in self.model.ep_info_buffer]):.1f}")
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


class PolicyCheckpoint(BaseCallback):
    """Save the policy (no pickle) every ``freq`` environment steps (``status``, ``bumper``:
    its observation has the belief status, the bumper; see :func:`agents.ppo.save_policy`)."""

    def __init__(self, folder: Path, freq: int, status: bool = False,
                 bumper: bool = False) -> None:
        super().__init__()
        self.folder, self.freq, self.last = folder, freq, 0
        self.status, self.bumper = status, bumper

    def _on_step(self) -> bool:
        if self.num_timesteps - self.last >= self.freq:
            self.last = self.num_timesteps
            save_policy(self.model, self.folder / f"policy_{self.num_timesteps}",
                        status=self.status, bumper=self.bumper)
        return True


def make_vec_env(args: TrainConfig, localizer: AppearanceLocalizer | None, n: int, seed: int,
                 kind: str = "dummy", check_city: bool = True) -> VecEnv:
    """``n`` navigation envs on the pose source, seeded from ``seed``, in this process
    (``kind="dummy"``) or each in a forked worker (``"subproc"``: the workers inherit the
    loaded localizer, nothing is pickled; fork before this process opens a GL context).
    ``check_city=False`` skips the belief's city check (done once in this process instead)."""
    def make() -> NavigationObservation:
        env = make_pose_env(args.pose_source, localizer, measurement=args.measurement or None,
                            scene_seed=args.scene_seed, city_size=args.city_size,
                            camera=args.camera, image_size=(args.image_size, args.image_size),
                            motion_noise=args.motion_noise,
                            max_episode_steps=args.max_episode_steps or None, start=args.start,
                            **args.source_options(),
                            **city_options(args.pose_source,
                                           args.allow_other_city or not check_city))
        reward = StreetProgressReward(env, uncertainty_penalty=args.uncertainty_penalty)
        return Monitor(NavigationObservation(reward, status=args.status, bumper=args.bumper))
    if kind not in VEC_ENVS:
        raise ValueError(f"unknown vec_env {kind!r}; choose one of {VEC_ENVS}")
    venv = SubprocVecEnv([make] * n, start_method="fork") if kind == "subproc" \
        else DummyVecEnv([make] * n)
    venv.seed(seed)
    return venv


def train_agent(args: TrainConfig) -> dict:
    """Train PPO as ``args`` says; write the policy, logs and ``train.json`` under
    ``<out>/<pose_source>/``; return the summary of ``train.json``."""
    torch.set_num_threads(args.threads)
    out = Path(args.out) / args.pose_source
    out.mkdir(parents=True, exist_ok=True)
    localizer = None
    if args.pose_source != "oracle":
        localizer = load_localizer(args.localizer)
    # fork the workers first (before this process opens a GL context); the city is checked
    # once, in this process, by the evaluation env's BeliefWrapper (OtherCityError)
    venv = make_vec_env(args, localizer, args.n_envs, args.seed, args.vec_env, check_city=False)
    try:
        eval_env = make_vec_env(args, localizer, 1, args.seed + 1_000_000)
    except ValueError:
        venv.close()
        raise
    model = make_ppo(venv, seed=args.seed, n_steps=args.n_steps, batch_size=args.batch_size)
    model.set_logger(configure(str(out), ["csv"]))
    evaluation = EvalCallback(eval_env, n_eval_episodes=args.eval_episodes,
                              eval_freq=max(args.eval_freq // args.n_envs, 1),
                              log_path=str(out), deterministic=True, verbose=0)
    callbacks = CallbackList([ProgressBar(args.total_timesteps, args.progress), evaluation,
                              PolicyCheckpoint(out / "checkpoints", args.checkpoint_freq,
                                               args.status, args.bumper)])
    t0 = time.perf_counter()
    model.learn(args.total_timesteps, callback=callbacks)
    seconds = time.perf_counter() - t0
    policy = save_policy(model, out / "policy", status=args.status, bumper=args.bumper,
                         pose_source=args.pose_source, scene_seed=args.scene_seed,
                         settings=dataclasses.asdict(args))
    successes = getattr(evaluation, "evaluations_successes", [])
    summary = {
        "args": dataclasses.asdict(args), "train_seconds": round(seconds, 1),
        "steps_per_second": round(args.total_timesteps / seconds, 1), "policy": str(policy),
        "final_eval_success_rate": float(np.mean(successes[-1])) if successes else None,
        "final_eval_return": float(evaluation.last_mean_reward),
    }
    (out / "train.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    venv.close()
    eval_env.close()
    return summary
