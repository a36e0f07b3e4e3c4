"""The env's side of the appearance conditions: the model parts they need, the per-episode
random streams, and applying a look (:class:`ConditionsRuntime`).

Seeding (so the same seed gives the same conditions and images, and nothing but the seed
changes them): ``reset(seed=s)`` starts a ``SeedSequence([s, STREAM])``; every reset spawns
the next child of it, which gives the episode's conditions and traffic (one generator) and
its sensor noise (another). The env's ``np_random`` (poses, goals, motion noise) is never
touched, so poses and goals are those of an env without conditions.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.camera_effects import NoiseBank, apply_camera_effects, focal_length_px
from envs.conditions import DEFAULT, Conditions, ConditionsSpec, parse_conditions
from envs.lighting import Lighting, lamps_xml
from envs.robot import CAMERA_FOVY
from envs.traffic import Traffic, traffic_xml

__all__ = ["STREAM", "ConditionsRuntime"]

STREAM = 0x636F6E64  # "cond": the conditions' own seed stream


class ConditionsRuntime:
    """Conditions of one env.

    Parameters
    ----------
    conditions : anything :func:`envs.conditions.parse_conditions` takes.
    city : envs.scene.City
    """

    def __init__(self, conditions: object, city: Any) -> None:
        self.spec: ConditionsSpec = parse_conditions(conditions)
        self.city = city
        self.current: Conditions = DEFAULT
        self.info: dict[str, Any] = DEFAULT.to_info()
        self.lighting: Lighting | None = None
        self.traffic: Traffic | None = None
        self._seq: np.random.SeedSequence | None = None
        self._rng = np.random.default_rng(0)
        self._noise = NoiseBank(np.random.default_rng(0))

    # ------------------------------------------------------------------ model
    def xml(self) -> tuple[str, str, str]:
        """(assets, world bodies, sensors) XML the conditions need in the model."""
        assets, bodies, sensors = "", "", ""
        if self.spec.lamps:
            assets, bodies = lamps_xml(self.city)
        nv, npd = self.spec.max_vehicles, self.spec.max_pedestrians
        if nv + npd:
            movers, sensors = traffic_xml(nv, npd)
            bodies += "\n" + movers
        return assets, bodies, sensors

    def bind(self, model: mujoco.MjModel) -> None:
        """Attach to the compiled model (after :meth:`xml` went into it)."""
        if not self.spec.is_default:
            self.lighting = Lighting(model, self.city)
        nv, npd = self.spec.max_vehicles, self.spec.max_pedestrians
        if nv + npd:
            self.traffic = Traffic(model, self.city, nv, npd)

    # ------------------------------------------------------------------ episodes
    def new_episode(self, seed: int | None) -> None:
        """Start the streams of an episode (``seed`` as passed to ``reset``)."""
        if self.spec.is_default:
            return
        if seed is not None or self._seq is None:
            self._seq = np.random.SeedSequence(None if seed is None else [seed, STREAM])
        looks, noise = self._seq.spawn(1)[0].spawn(2)
        self._rng, self._noise = np.random.default_rng(looks), NoiseBank(np.random.default_rng(noise))

    def draw(self, data: mujoco.MjData, cameras: list[Any], robot_xy: NDArray[np.float64]) -> None:
        """Draw the next conditions of the episode and apply them (see :meth:`apply`)."""
        if not self.spec.is_default:
            self.apply(self.spec.draw(self._rng), data, cameras, robot_xy)

    def apply(self, c: Conditions, data: mujoco.MjData, cameras: list[Any],
              robot_xy: NDArray[np.float64]) -> None:
        """Apply ``c``: light, fog and tints, and spawn its traffic (away from ``robot_xy``).

        Raises
        ------
        ValueError
            If ``c`` needs street lamps or more movers than the model was built with.
        """
        if not isinstance(c, Conditions):
            raise TypeError(f"conditions must be a Conditions, got {type(c).__name__}")
        self._check_capacity(c)
        if self.lighting is not None:
            self.lighting.apply(c, data, cameras)
        if self.traffic is not None:
            self.traffic.spawn(data, self._rng, robot_xy, c.vehicles, c.pedestrians)
        self.current = c
        self.info = c.to_info()

    def _check_capacity(self, c: Conditions) -> None:
        spec = self.spec
        if c == DEFAULT or c == spec.conditions:
            return
        if spec.is_default:
            raise ValueError("this env was made without conditions: make it with "
                             "conditions=... to change its look")
        if c.lamps > 0 and not spec.lamps:
            raise ValueError("conditions lamps > 0 need street lamps in the model: make the env "
                             "with conditions that can light them (e.g. 'night' or 'random')")
        for name, cap in (("vehicles", spec.max_vehicles), ("pedestrians", spec.max_pedestrians)):
            if getattr(c, name) > cap:
                raise ValueError(f"conditions {name}={getattr(c, name)} exceeds the {cap} the "
                                 f"env was made with")

    # ------------------------------------------------------------------ steps
    @property
    def lamps_on(self) -> bool:
        """Whether street lamps are lit (their heads follow the camera)."""
        return self.lighting is not None and self.lighting.lamps_on

    def place_lamp_heads(self, data: mujoco.MjData, pose: NDArray[np.float64]) -> None:
        """Put the lamp heads at the lamps nearest ahead of the robot at ``pose``."""
        if self.lighting is not None:
            self.lighting.place_heads(data, pose)

    def advance(self, data: mujoco.MjData, dt: float, robot_xy: NDArray[np.float64]) -> None:
        """Move the traffic ``dt`` seconds."""
        if self.traffic is not None:
            self.traffic.advance(data, dt, robot_xy)

    def hit(self, data: mujoco.MjData) -> bool:
        """Whether the robot touches a mover."""
        return self.traffic is not None and self.traffic.hit(data)

    def camera_image(self, image: NDArray[np.uint8], speed: float, turn_rate: float
                     ) -> NDArray[np.uint8]:
        """The rendered ``image`` (H, W, 3) as the camera records it (blur, exposure, noise)."""
        c = self.current
        if not c.has_camera_effects:
            return image
        f = focal_length_px(CAMERA_FOVY, image.shape[0])
        return apply_camera_effects(image, c, speed, turn_rate, f, self._noise)
