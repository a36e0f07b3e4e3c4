"""PPO (stable-baselines3) on the navigation observation, saved and loaded without pickle.

:func:`make_ppo` builds the model ``appearance-nav train`` trains (``MultiInputPolicy`` on
:class:`agents.observations.NavigationObservation`). stable-baselines3's own ``.zip`` format
unpickles parts of the model on load, so policies are saved here as a torch state dict
(``<path>.pt``, loaded with ``torch.load(weights_only=True)``) plus JSON settings
(``<path>.json``): :func:`save_policy`, :func:`load_policy`. :class:`PPOAgent` acts with a
loaded policy on pose-belief observations, with the same ``act(obs)`` interface as
:class:`agents.scripted.ScriptedAgent`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from numpy.typing import NDArray
from stable_baselines3 import PPO
from stable_baselines3.common.policies import MultiInputActorCriticPolicy

from agents.observations import NavigationFeatures

__all__ = ["PPO_DEFAULTS", "PPOAgent", "load_policy", "make_ppo", "save_policy"]

FORMAT = "appearance-nav-ppo-policy/1"
PPO_DEFAULTS: dict[str, Any] = {
    "n_steps": 512,
    "batch_size": 256,
    "n_epochs": 10,
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "ent_coef": 0.0,
    "clip_range": 0.2,
    "policy_kwargs": {"net_arch": [64, 64]},
}
ACTION_SPACE = spaces.Box(-1.0, 1.0, (2,), np.float32)


def make_ppo(env: gym.Env | Any, seed: int = 0, **overrides: Any) -> PPO:
    """A ``PPO("MultiInputPolicy", env)`` with :data:`PPO_DEFAULTS` (overridable), on the CPU."""
    kwargs = {**PPO_DEFAULTS, **overrides}
    return PPO("MultiInputPolicy", env, seed=seed, device="cpu", verbose=0, **kwargs)


def save_policy(model: PPO, path: str | Path, lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                **meta: Any) -> Path:
    """Write ``<path>.pt`` (policy state dict) and ``<path>.json`` (settings); return the .pt path."""
    path = Path(path).with_suffix("")
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(model.policy.state_dict(), path.with_suffix(".pt"))
    settings = {"format": FORMAT, "policy_kwargs": model.policy_kwargs,
                "lookaheads": list(lookaheads), "meta": meta}
    path.with_suffix(".json").write_text(json.dumps(settings, indent=2, default=str))
    return path.with_suffix(".pt")


def load_policy(path: str | Path) -> tuple[MultiInputActorCriticPolicy, dict[str, Any]]:
    """Load a policy written by :func:`save_policy`: (policy in eval mode, settings).

    Raises
    ------
    FileNotFoundError
        If ``<path>.pt`` or ``<path>.json`` is missing.
    ValueError
        If the files are not a saved policy or do not match the navigation observation.
    """
    path = Path(path).with_suffix("")
    weights, settings_file = path.with_suffix(".pt"), path.with_suffix(".json")
    for f in (weights, settings_file):
        if not f.exists():
            raise FileNotFoundError(f"no saved PPO policy file {f}")
    try:
        settings = json.loads(settings_file.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{settings_file} is not valid JSON: {err}") from None
    if settings.get("format") != FORMAT:
        raise ValueError(f"{settings_file}: unknown policy format {settings.get('format')!r}")
    space = NavigationFeatures.space(tuple(settings["lookaheads"]))
    policy = MultiInputActorCriticPolicy(space, ACTION_SPACE, lambda _: 0.0,
                                         **settings["policy_kwargs"])
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
        policy.load_state_dict(state, strict=True)
    except (RuntimeError, KeyError, ValueError) as err:
        raise ValueError(f"{weights} does not hold this policy's weights: {err}") from err
    return policy.eval(), settings


class PPOAgent:
    """A trained PPO policy acting on pose-belief observations.

    Parameters
    ----------
    policy : stable_baselines3 MultiInputActorCriticPolicy — trained on
        :class:`NavigationObservation` observations (``model.policy`` or :func:`load_policy`).
    city : envs.scene.City — the map the navigation observation is planned on.
    lookaheads : tuple of float — must match the training wrapper's.
    deterministic : bool — act with the mean action (True) or sample.
    """

    def __init__(self, policy: MultiInputActorCriticPolicy, city: Any,
                 lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                 deterministic: bool = True) -> None:
        self.policy = policy
        self.features = NavigationFeatures(city, lookaheads)
        if policy.observation_space != self.features.observation_space:
            raise ValueError("the policy was trained on another observation space: "
                             f"{policy.observation_space} != {self.features.observation_space}")
        self.deterministic = deterministic

    @classmethod
    def load(cls, path: str | Path, city: Any, deterministic: bool = True) -> PPOAgent:
        """Load a policy saved by :func:`save_policy`."""
        policy, settings = load_policy(path)
        return cls(policy, city, tuple(settings["lookaheads"]), deterministic)

    def reset(self) -> None:
        """Forget the plan (call between episodes)."""
        self.features.reset()

    def act(self, obs: Mapping[str, Any]) -> NDArray[np.float32]:
        """The action U = [v, w] for one belief observation."""
        action, _ = self.policy.predict(self.features(obs), deterministic=self.deterministic)
        return np.asarray(action, dtype=np.float32)
