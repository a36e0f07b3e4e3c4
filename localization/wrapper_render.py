"""``render()`` of the pose wrappers (:mod:`localization.wrappers`): the belief on the map.

:class:`RenderBelief` is the part of every pose wrapper that draws. On the step path it only
keeps references to the last observation and ``info`` (no copy, no drawing); ``render()``
builds a :class:`~localization.belief_render.BeliefFrame` from them and the wrapper's belief,
and draws it with a :class:`~localization.belief_render.BeliefRenderer` made on the first
call from the env's city (``env.unwrapped.top_down_map()``, read duck-typed: this layer does
not import ``envs``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from localization._validation import check_array
from localization.belief_render import BeliefFrame, BeliefRenderer
from localization.geometry import Array

__all__ = ["RenderBelief"]


class RenderBelief:
    """Mixin of the pose wrappers: :attr:`planned_path`, :meth:`render`, :meth:`render_frame`.

    The wrapper sets ``mean`` / ``cov`` (and, with a particle filter, ``belief``) and calls
    :meth:`_see` with each observation and ``info``; :attr:`render_title` heads the status.
    """

    render_title = "pose belief"
    env: Any
    mean: Array | None
    cov: Array | None

    def __init__(self) -> None:
        self._planned_path: Array | None = None
        self._renderer: BeliefRenderer | None = None
        self._seen: tuple[dict[str, Any] | None, dict[str, Any] | None] = (None, None)

    @property
    def planned_path(self) -> Array | None:
        """The planned path (p, 2) that :meth:`render` draws, or None. Set it from the agent
        each step (through other wrappers: ``env.set_wrapper_attr("planned_path",
        agent.path)``); the wrapper never plans."""
        return self._planned_path

    @planned_path.setter
    def planned_path(self, path: ArrayLike | None) -> None:
        self._planned_path = None if path is None else check_array(
            path, "planned_path", shape=(None, 2), what="[x, y] waypoints")

    def render(self) -> NDArray[np.uint8] | None:
        """The belief on the city map, ``(384, 576, 3)`` uint8: the map with the true pose
        (black), the belief mean (blue) and its 2-sigma position ellipse, the particles and
        the other hypotheses (particle filter), the goal and the planned path; on the right
        the camera image and the status (:mod:`localization.belief_render`). None when the
        env has no render mode.

        Raises
        ------
        TypeError
            If the env has no ``top_down_map()`` (``AppearanceNav-v0`` has it).
        """
        if self.env.render_mode is None:
            return None
        if self._renderer is None:
            city_map = getattr(self.env.unwrapped, "top_down_map", None)
            if not callable(city_map):
                raise TypeError("render() draws the city of env.unwrapped.top_down_map() "
                                "(AppearanceNav-v0 has it); "
                                f"{type(self.env.unwrapped).__name__} has none")
            self._renderer = BeliefRenderer(city_map())
        return self._renderer.draw(self.render_frame())

    def render_frame(self) -> BeliefFrame:
        """What :meth:`render` draws now: the belief, the last observation and ``info``."""
        obs, info = (s or {} for s in self._seen)
        return BeliefFrame(mean=self.mean, cov=self.cov, true_pose=info.get("pose"),
                           goal=obs.get("goal"), path=self._planned_path,
                           image=obs.get("image"), lines=self._status_lines(info),
                           **self._belief_extras())

    def _see(self, observation: dict[str, Any] | None = None,
             info: dict[str, Any] | None = None) -> None:
        """Keep references to the last observation / info (the only work on the step path)."""
        self._seen = (self._seen[0] if observation is None else observation,
                      self._seen[1] if info is None else info)

    def _belief_extras(self) -> dict[str, Any]:
        """The particles, their weights and the other hypotheses, when the filter has them."""
        belief = getattr(self, "belief", None)
        if getattr(belief, "particles", None) is None:
            return {}
        return {"particles": belief.particles, "weights": belief.weights,
                "hypotheses": belief.hypotheses["means"][1:]}

    def _status_lines(self, info: dict[str, Any]) -> tuple[str, ...]:
        lines = [self.render_title]
        for key, label in (("belief_status", "belief"), ("measurement_status", "measurement")):
            if key in info:
                lines.append(f"{label}: {info[key]}")
        if np.isfinite(info.get("nis", np.nan)):
            lines.append(f"NIS {info['nis']:.2f} ({info.get('nis_dof', '?')} dof)")
        if "nees" in info:
            lines.append(f"NEES {info['nees']:.2f}")
        if "pose" in info and self.mean is not None:
            error = float(np.hypot(*(np.asarray(info["pose"])[:2] - self.mean[:2])))
            lines.append(f"error {error:.2f} m")
        if info.get("kidnapped"):
            lines.append("KIDNAPPED this step")
        return tuple(lines)
