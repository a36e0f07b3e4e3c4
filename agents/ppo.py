"""PPO (stable-baselines3) on the navigation observation, saved and loaded without pickle.

:func:`make_ppo` builds the model ``appearance-nav train`` trains (``MultiInputPolicy`` on
:class:`agents.observations.NavigationObservation`). stable-baselines3's own ``.zip`` format
unpickles parts of the model on load, so policies are saved here as a torch state dict
(``<path>.pt``, loaded with ``torch.load(weights_only=True)``) plus JSON settings
(``<path>.json``): :func:`save_policy`, :func:`load_policy`. :class:`PPOAgent` acts with a
loaded policy on pose-belief observations, with the same ``act(obs)`` interface as
:class:`agents.scripted.ScriptedAgent` (``act(obs, info)`` for a policy that sees the belief
status or the bumper). ``policy.json`` records the observation settings (``lookaheads``,
``status``, ``bumper``); a file without ``status`` or ``bumper`` (written before they existed)
is a policy without them.
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
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.policies import MultiInputActorCriticPolicy

from agents.observations import NavigationFeatures
from localization._validation import check_array, check_bool, check_seed

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
    """A ``PPO("MultiInputPolicy", env)`` with :data:`PPO_DEFAULTS` (overridable), on the CPU.

    Without a ``tensorboard_log`` it logs nowhere (``model.set_logger`` to log):
    stable-baselines3's default logger makes an empty ``SB3-<time>`` folder in the temp
    directory at every ``learn``."""
    check_seed(seed, "seed")
    kwargs = {**PPO_DEFAULTS, **overrides}
    model = PPO("MultiInputPolicy", env, seed=seed, device="cpu", verbose=0, **kwargs)
    if kwargs.get("tensorboard_log") is None:
        model.set_logger(Logger(None, []))
    return model


def save_policy(model: PPO, path: str | Path, lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                status: bool = False, bumper: bool = False, **meta: Any) -> Path:
    """Write ``<path>.pt`` (policy state dict) and ``<path>.json`` (settings: the observation's
    ``lookaheads``, ``status`` and ``bumper``, see :class:`NavigationFeatures`); return the .pt
    path."""
    path = _check_path(path).with_suffix("")
    status, bumper = check_bool(status, "status"), check_bool(bumper, "bumper")
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(model.policy.state_dict(), path.with_suffix(".pt"))
    settings = {"format": FORMAT, "policy_kwargs": model.policy_kwargs,
                "lookaheads": list(lookaheads), "status": status, "bumper": bumper,
                "meta": meta}
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
    path = _check_path(path).with_suffix("")
    weights, settings_file = path.with_suffix(".pt"), path.with_suffix(".json")
    for f in (weights, settings_file):
        if not f.is_file():
            raise FileNotFoundError(f"no saved PPO policy file {f}")
    settings = _read_settings(settings_file)
    space = NavigationFeatures.space(tuple(settings["lookaheads"]), settings["status"],
                                     settings["bumper"])
    try:
        policy = MultiInputActorCriticPolicy(space, ACTION_SPACE, lambda _: 0.0,
                                             **settings["policy_kwargs"])
    except (TypeError, ValueError) as err:
        raise ValueError(f"{settings_file}: policy_kwargs do not build a policy: {err}") from None
    state = _read_weights(weights)
    try:
        policy.load_state_dict(state, strict=True)
    except (RuntimeError, KeyError, ValueError, TypeError) as err:
        raise ValueError(f"{weights} does not hold this policy's weights: {err}") from None
    return policy.eval(), settings


def _check_path(path: object) -> Path:
    if not isinstance(path, (str, Path)):
        raise TypeError(f"path must be a str or pathlib.Path, got {type(path).__name__}")
    return Path(path)


def _read_settings(settings_file: Path) -> dict[str, Any]:
    """The JSON settings of a saved policy, checked for the keys :func:`load_policy` uses."""
    try:
        settings = json.loads(settings_file.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{settings_file} is not a policy settings file (not valid JSON: {err})"
                         ) from None
    if not isinstance(settings, dict):
        raise ValueError(f"{settings_file} is not a policy settings file (a JSON "  # noqa: TRY004  (a bad file is a bad value)
                         f"{type(settings).__name__}, not an object)")
    if settings.get("format") != FORMAT:
        raise ValueError(f"{settings_file}: unknown policy format {settings.get('format')!r}")
    missing = [k for k in ("policy_kwargs", "lookaheads") if k not in settings]
    if missing:
        raise ValueError(f"{settings_file} is not a complete policy settings file: "
                         f"missing key(s) {missing}")
    if not isinstance(settings["policy_kwargs"], dict):
        raise ValueError(f"{settings_file}: policy_kwargs must be a JSON object")  # noqa: TRY004  (a bad file is a bad value)
    try:
        lookaheads = check_array(settings["lookaheads"], "lookaheads", ndim=1)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{settings_file}: bad lookaheads: {err}") from None
    if len(lookaheads) == 0 or np.any(lookaheads <= 0):
        raise ValueError(f"{settings_file}: lookaheads must be positive distances, "
                         f"got {settings['lookaheads']}")
    for key in ("status", "bumper"):
        settings.setdefault(key, False)  # files from before the status / bumper observation
        if not isinstance(settings[key], bool):
            raise ValueError(f"{settings_file}: {key} must be true or false, "  # noqa: TRY004  (a bad file is a bad value)
                             f"got {settings[key]!r}")
    return settings


def _read_weights(weights: Path) -> dict[str, Any]:
    """``torch.load(weights_only=True)`` of a policy state dict; any failure (truncated, empty,
    not a torch file, or a pickle needing arbitrary code) is a ValueError naming the file. The
    loader's own advice to retry with ``weights_only=False`` is deliberately not passed on:
    that would run code from an untrusted file."""
    try:
        state = torch.load(weights, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001  (torch raises OSError, EOFError, UnpicklingError, ...)
        raise ValueError(f"{weights} is not a policy file: torch could not load it as plain "
                         f"weights ({type(err).__name__}); is it truncated or another file?"
                         ) from None
    if not isinstance(state, dict):
        raise ValueError(f"{weights} is not a policy file: it holds a {type(state).__name__}, "  # noqa: TRY004  (a bad file is a bad value)
                         f"not a state dict")
    return state


class PPOAgent:
    """A trained PPO policy acting on pose-belief observations.

    Parameters
    ----------
    policy : stable_baselines3 MultiInputActorCriticPolicy — trained on
        :class:`NavigationObservation` observations (``model.policy`` or :func:`load_policy`).
    city : envs.scene.City — the map the navigation observation is planned on.
    lookaheads : tuple of float — must match the training wrapper's.
    deterministic : bool — act with the mean action (True) or sample.
    status : bool — the policy sees the belief status (must match the training wrapper's).
    bumper : bool — the policy feels the bump sensor (must match the training wrapper's).
    """

    def __init__(self, policy: MultiInputActorCriticPolicy, city: Any,
                 lookaheads: tuple[float, ...] = (0.5, 1.0, 2.0),
                 deterministic: bool = True, status: bool = False,
                 bumper: bool = False) -> None:
        self.policy = policy
        self.features = NavigationFeatures(city, lookaheads, status=status, bumper=bumper)
        if policy.observation_space != self.features.observation_space:
            raise ValueError("the policy was trained on another observation space: "
                             f"{policy.observation_space} != {self.features.observation_space}")
        self.deterministic = deterministic

    @classmethod
    def load(cls, path: str | Path, city: Any, deterministic: bool = True) -> PPOAgent:
        """Load a policy saved by :func:`save_policy`."""
        policy, settings = load_policy(path)
        return cls(policy, city, tuple(settings["lookaheads"]), deterministic,
                   settings["status"], settings["bumper"])

    def reset(self) -> None:
        """Forget the plan and the last contact (call between episodes)."""
        self.features.reset()

    def act(self, obs: Mapping[str, Any], info: Mapping[str, Any] | None = None,
            ) -> NDArray[np.float32]:
        """The action U = [v, w] for one belief observation (``info``: the step's, for its
        ``belief_status``, None or without it: "tracking"; and its ``collision`` and
        ``collision_bearing`` for a policy with the bumper). Call once per env step."""
        status = None if info is None else info.get("belief_status")
        action, _ = self.policy.predict(self.features(obs, status, info),
                                        deterministic=self.deterministic)
        return np.asarray(action, dtype=np.float32)
