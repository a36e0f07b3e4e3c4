"""The env settings shared by agent training and evaluation (``appearance-nav train`` / ``eval``)."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["AgentEnvSettings", "city_options"]


@dataclass
class AgentEnvSettings:
    """The city, camera and pose source settings of an agent's env (one definition for the
    ``train`` and ``eval`` commands, so both build the same env)."""

    localizer: str = field(default="results/localizer.npz", metadata={
        "help": "fitted AppearanceLocalizer (belief and dead_reckoning; make demo writes it)"})
    measurement: str = field(default="", metadata={
        "help": "belief measurement model (empty: BeliefWrapper's default)"})
    scene_seed: int = field(default=0, metadata={"help": "the city"})
    city_size: float = field(default=20.0, metadata={
        "help": "side of the square city (m; 60: nine times the default area)"})
    camera: str = field(default="perspective", metadata={"help": "env camera"})
    image_size: int = field(default=64, metadata={"help": "side of the square camera image"})
    motion_noise: float = field(default=0.1, metadata={
        "help": "actuation noise of the env (the localizer's noise model is fitted at one level)"})
    start: str = field(default="lane", metadata={
        "help": "episode starts: 'lane' (on a street, facing along it) or 'random' (any free pose)"})
    max_episode_steps: int = field(default=0, metadata={
        "help": "episode truncation (0: 20 steps per metre of city side, 400 in the default "
                "city)"})
    allow_other_city: bool = field(default=False, metadata={
        "help": "run a localizer fitted on another city (refused by default)"})


def city_options(source: str, allow_other_city: bool) -> dict[str, bool]:
    """``make_pose_env`` keywords for the city check: only the belief runs the localizer's maps
    (dead reckoning takes only its Q, the oracle nothing)."""
    return {"allow_other_city": allow_other_city} if source == "belief" else {}
