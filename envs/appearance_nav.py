"""``AppearanceNav-v0``: drive a differential-drive robot through a generated city.

The robot sees the city only through its camera; the true pose is reported in
``info["pose"]`` for training localizers and for evaluation, never in the
observation.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from numpy.typing import ArrayLike, NDArray

from envs.cameras import TopDownView, check_image_size, make_camera
from envs.conditions import Conditions
from envs.conditions_runtime import ConditionsRuntime
from envs.lookalike import LookalikeCity, generate_lookalike_city
from envs.motion_model import UnicycleModel, wrap_angle
from envs.robot import (
    ACTUATOR_XML,
    HALF_TRACK,
    ROBOT_GEOMS,
    ROBOT_RADIUS,
    ROBOT_XML,
    SENSOR_XML,
    WHEEL_RADIUS,
    contact_bearing,
)
from envs.scene import City, generate_city
from envs.top_down import TopDownMap, top_down_map
from envs.upright import TIPPED_OVER_TILT, Upright
from localization._validation import (
    check_array,
    check_choice,
    check_int,
    check_options,
    check_real,
    check_seed,
)

__all__ = ["CITY_LAYOUTS", "RESET_OPTIONS", "AppearanceNavEnv", "make_appearance_nav"]

#: the values of ``city_layout``
CITY_LAYOUTS = ("random", "lookalike")

#: the keys ``reset(options=...)`` understands
RESET_OPTIONS = ("pose", "goal")

Obs = dict[str, NDArray[Any]]


class AppearanceNavEnv(gym.Env[Obs, NDArray[np.float32]]):
    """Reach a goal on the streets of a procedurally generated MuJoCo city.

    Parameters
    ----------
    scene_seed : int
        Names the city (``envs.scene.generate_city``); different seeds give different cities.
    camera : str
        A camera registered in ``envs.cameras.CAMERAS`` ("perspective", and "fisheye" /
        "catadioptric" when ``envs.cube_camera`` is present).
    image_size : (H, W) ints in [16, 1024].
    max_episode_steps : int or None
        Truncate after this many steps (``None``: never). ``gymnasium.make`` adds its own
        limit: ``envs.episode_steps(city_size)`` (25 steps per metre of city side: 500 for
        the default city, 1500 for a 60 m one; :class:`envs.time_limit.CityTimeLimit`), or
        its ``TimeLimit(N)`` for ``gymnasium.make(..., max_episode_steps=N)``.
    motion_noise : float >= 0
        Scale of the actuation error: each wheel speed command ``q`` becomes
        ``q (1 + s e1) + s * ADDITIVE_WHEEL_NOISE * e2`` with standard normal ``e1, e2``
        drawn from ``self.np_random``. 0 leaves only the physics (inertia, contacts, slip).
    render_mode : "rgb_array" or None
        ``render()`` returns a top-down (north-up) map with the robot and the goal.
    city_size, block_size, street_width : float
        City layout in metres (default 20 x 20 m, 4 m blocks, 2 m streets). Bigger cities
        keep the block size (a 60 m city has 9 x 9 blocks, 7.8 times the street area:
        :meth:`envs.scene.City.street_area`), their floor and horizon textures the default
        city's texel size (up to a 164 m city) and their skyline its density.
    frame_skip : int
        Physics steps (0.01 s each) per env step; ``dt = 0.01 * frame_skip`` (default 0.1 s).
    city_layout : {"random", "lookalike"}
        "random" (default): every block drawn anew, with tall landmark towers.
        "lookalike": every block the same block (:mod:`envs.lookalike`), except for
        ``n_landmarks`` landmark buildings (same shape, a saturated colour), so single images
        cannot tell twin places apart; twins differ by multiples of ``self.city.period``
        along x and y, and ``info["twins"]`` lists the true pose's twins.
    n_landmarks : int or None
        Landmark buildings (default 3 for "random", 2 for "lookalike").
    conditions : None, str, dict or envs.conditions.Conditions
        The look of the episodes (:mod:`envs.conditions`): None / "default" (today's look),
        a preset ("dusk", "night", "overcast", "fog", "seasonal", "exposure", "noise",
        "motion_blur", "traffic"), "random" (drawn per episode from the reset seed), or
        ``{"preset": name, **fields}``. Vehicles and pedestrians move along the streets
        (:mod:`envs.traffic`) and count as collisions when they touch the robot.

    Notes
    -----
    Action ``U = [v, w]``: commanded linear (m/s) and angular (rad/s) velocity in the Box
    ``[-1, 1]^2`` (float32). Finite out-of-range actions are clipped to the Box; NaN/inf or
    a shape other than (2,) raise ``ValueError``. ``dt = 0.1`` s by default; the known motion
    model is ``self.motion_model = UnicycleModel(dt)``.

    Observation ``{"image": (H, W, 3) uint8, "goal": (2,) float32 world position}``.
    ``info``: ``pose`` [x, y, yaw] float64 (the true pose, never in the observation),
    ``collision`` (the robot touched a building, the city's invisible boundary wall or a
    moving object during the step), ``collision_with`` (what it touched: a tuple of
    ``"city"`` (buildings and the boundary) and ``"traffic"`` (vehicles and pedestrians),
    empty without contact), ``collision_bearing`` (rad, counter-clockwise from the heading:
    where the robot touched the city first in the step, 0 ahead, +-pi behind, what a ring
    bumper reports; None without a city contact), ``tipped_over`` (tilted past ``envs.upright.TIPPED_OVER_TILT``, on
    its side or back; the upright torque rights it), ``distance_to_goal`` (m), ``control``
    (the clipped U applied); with
    ``city_layout="lookalike"`` also ``twins`` (m, 3): the true pose's twin poses in the city
    (:meth:`envs.lookalike.LookalikeCity.twins`); ``conditions`` (dict): the episode's
    conditions (:meth:`envs.conditions.Conditions.to_info`; ``holds`` lists those that
    differ from today's look).

    Reward: decrease of the distance to the goal minus ``STEP_COST`` minus
    ``COLLISION_PENALTY`` on collision; terminated within ``GOAL_RADIUS`` of the goal.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    V_MAX = 1.0  # m/s
    W_MAX = 1.0  # rad/s
    GOAL_RADIUS = 0.5  # m
    STEP_COST = 0.01
    COLLISION_PENALTY = 0.1
    ADDITIVE_WHEEL_NOISE = 2.0  # rad/s of wheel speed per unit motion_noise
    MIN_GOAL_DISTANCE = 2.0  # m, for random goals

    def __init__(
        self,
        scene_seed: int = 0,
        camera: str = "perspective",
        image_size: tuple[int, int] = (64, 64),
        max_episode_steps: int | None = None,
        motion_noise: float = 0.0,
        render_mode: str | None = "rgb_array",
        city_size: float = 20.0,
        block_size: float = 4.0,
        street_width: float = 2.0,
        frame_skip: int = 10,
        city_layout: str = "random",
        n_landmarks: int | None = None,
        conditions: object = None,
    ) -> None:
        self.image_size = check_image_size(image_size)
        self.motion_noise = check_real(motion_noise, "motion_noise", low=0.0)
        check_choice(render_mode, "render_mode", (None, *self.metadata["render_modes"]))
        if max_episode_steps is not None:
            max_episode_steps = check_int(max_episode_steps, "max_episode_steps", low=1)
        frame_skip = check_int(frame_skip, "frame_skip", low=1)
        if not isinstance(camera, str):
            raise TypeError(f"camera must be a camera name (str), got {type(camera).__name__}")
        scene_seed = check_seed(scene_seed, "scene_seed")
        self.render_mode = render_mode
        self.max_episode_steps = max_episode_steps
        self.frame_skip = int(frame_skip)

        self.city_layout = check_choice(city_layout, "city_layout", CITY_LAYOUTS)
        if n_landmarks is not None:
            n_landmarks = check_int(n_landmarks, "n_landmarks", low=0)
        self.city: City = self._make_city(scene_seed, city_size, block_size, street_width,
                                          n_landmarks)
        self._conditions = ConditionsRuntime(conditions, self.city)
        assets, bodies, sensors = self._conditions.xml()
        self.model = mujoco.MjModel.from_xml_string(
            self.city.to_mjcf(ROBOT_XML + bodies, assets, ACTUATOR_XML, SENSOR_XML + sensors))
        self.city.paint_textures(self.model)
        self.data = mujoco.MjData(self.model)
        self.dt = self.model.opt.timestep * self.frame_skip
        self.motion_model = UnicycleModel(self.dt)
        self._conditions.bind(self.model)  # paints its textures: before the camera uploads them
        self.camera_name = camera
        self._camera = make_camera(camera, self.model, self.image_size)
        self._top_down: TopDownView | None = None
        self._init_ids()

        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        lo, hi = self.city.bounds
        self.observation_space = spaces.Dict(
            {
                "image": spaces.Box(0, 255, (*self.image_size, 3), np.uint8),
                "goal": spaces.Box(np.float32(lo), np.float32(hi), (2,), np.float32),
            }
        )
        self._goal = np.zeros(2)
        self._steps = 0
        self._distance = 0.0

    # ------------------------------------------------------------------ setup
    def _make_city(self, seed: int, size: float, block: float, street: float,
                   n_landmarks: int | None) -> City:
        if self.city_layout == "lookalike":
            return generate_lookalike_city(seed, size, block, street,
                                           n_landmarks=2 if n_landmarks is None else n_landmarks)
        return generate_city(seed, size, block, street,
                             n_landmarks=3 if n_landmarks is None else n_landmarks)

    def _init_ids(self) -> None:
        m = self.model
        root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "root")
        self._root_qpos, self._root_dof = m.jnt_qposadr[root], m.jnt_dofadr[root]
        self._upright = Upright(m)
        self._goal_mocap = m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "goal")]
        sensor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "collision")
        self._collision_adr = m.sensor_adr[sensor]
        self.robot_geom_ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in ROBOT_GEOMS]

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Obs, dict[str, Any]]:
        """Reset the robot (``options["pose"]`` = [x, y, yaw] or random) and the goal
        (``options["goal"]`` = [x, y] or a random street point).

        Raises
        ------
        TypeError
            If ``seed`` is not an integer or ``options`` not a dict.
        ValueError
            If ``seed`` is negative, ``options`` has a key other than "pose" and "goal", or
            the pose or goal is malformed, inside a building or outside the city.
        """
        seed = check_seed(seed, "seed", optional=True)
        options = check_options(options, "options", RESET_OPTIONS)
        super().reset(seed=seed)
        self._conditions.new_episode(seed)
        mujoco.mj_resetData(self.model, self.data)
        if options.get("pose") is not None:
            pose = self._check_point(options["pose"], 3, "pose", ROBOT_RADIUS)
        else:
            pose = self.city.random_free_pose(self.np_random, margin=ROBOT_RADIUS + 0.1)
        if options.get("goal") is not None:
            self._goal = self._check_point(options["goal"], 2, "goal", 0.0)
        else:
            self._goal = self._random_goal(pose[:2])
        self.data.mocap_pos[self._goal_mocap, :2] = self._goal
        self._conditions.draw(self.data, [self._camera], pose[:2])
        self.set_pose(pose)
        self._steps = 0
        self._distance = self._distance_to_goal()
        info = self._info((), control=np.zeros(2))
        info["collision_bearing"] = None
        return self._obs(), info

    def step(self, action: ArrayLike) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        """Apply ``U = [v, w]`` for ``dt`` seconds (see the class notes for clipping and errors)."""
        u = self._check_action(action)
        self.data.ctrl[:] = self._wheel_speeds(u)
        if self._conditions.traffic is not None:
            self._conditions.advance(self.data, self.dt, self.pose[:2])
        traffic_hit, bearing = False, None
        for _ in range(self.frame_skip):  # the contact sensor sees the state at the start of each substep
            self._upright.apply(self.data)
            mujoco.mj_step(self.model, self.data)
            if bearing is None and self.data.sensordata[self._collision_adr] > 0:
                bearing = contact_bearing(self.data.sensordata[self._collision_adr:], self.pose)
            traffic_hit = traffic_hit or self._conditions.hit(self.data)
        city_hit = bearing is not None
        collision = city_hit or traffic_hit
        self._sync_kinematics()
        self._steps += 1
        pose = self.pose
        distance = math.hypot(pose[0] - self._goal[0], pose[1] - self._goal[1])
        reward = (self._distance - distance) - self.STEP_COST - self.COLLISION_PENALTY * collision
        self._distance = distance
        terminated = distance < self.GOAL_RADIUS
        truncated = self.max_episode_steps is not None and self._steps >= self.max_episode_steps
        with_ = ("city",) * city_hit + ("traffic",) * traffic_hit
        info = self._info(with_, u, pose)
        info["collision_bearing"] = bearing
        return self._obs(), float(reward), bool(terminated), bool(truncated), info

    def render(self) -> NDArray[np.uint8] | None:
        """Return a top-down view (north up) of the city, robot and goal, or None without a render mode."""
        if self.render_mode is None:
            return None
        if self._top_down is None:
            self._top_down = TopDownView(self.city)
        return self._top_down.draw(self.pose, self._goal)

    def close(self) -> None:
        """Close the camera's renderer (idempotent)."""
        if getattr(self, "_camera", None) is not None:
            self._camera.close()
            self._camera = None  # type: ignore[assignment]

    # ------------------------------------------------------------------ pose
    @property
    def pose(self) -> NDArray[np.float64]:
        """The true pose ``[x, y, yaw]`` of the robot's free joint, float64 (3,)."""
        x, y, _, qw, qx, qy, qz = self.data.qpos[self._root_qpos : self._root_qpos + 7].tolist()
        # heading of the body x axis projected on the ground; atan2 is already in [-pi, pi]
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        return np.array([x, y, math.pi if yaw == -math.pi else yaw])

    @property
    def tilt(self) -> float:
        """Angle (rad) between the robot's up axis and the vertical: 0 upright, pi on its back."""
        return self._upright.tilt(self.data)

    @property
    def goal(self) -> NDArray[np.float64]:
        """The goal position [x, y], float64 (2,)."""
        return self._goal.copy()

    def set_pose(self, pose: ArrayLike) -> None:
        """Teleport the robot to ``pose`` [x, y, yaw] at rest and run ``mj_forward``.

        The pose must be finite with shape (3,); it is not checked against the buildings.
        """
        x, y, yaw = check_array(pose, "pose", shape=(3,), what="[x, y, yaw]")
        a = self._root_qpos
        self.data.qpos[a : a + 7] = [x, y, WHEEL_RADIUS, np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
        self.data.qvel[:] = 0.0
        self.data.ctrl[:] = 0.0
        mujoco.mj_forward(self.model, self.data)

    def top_down_map(self) -> TopDownMap:
        """The city from above as plain arrays (:class:`envs.top_down.TopDownMap`)."""
        return top_down_map(self.city)

    def render_camera(self) -> NDArray[np.uint8]:
        """Return the camera image at the current state, (H, W, 3) uint8 (with the
        conditions' camera effects: motion blur at the robot's speed, exposure, noise)."""
        if self._conditions.lamps_on:
            self._conditions.place_lamp_heads(self.data, self.pose)
        image = self._camera.render(self.data)
        if not self._conditions.current.has_camera_effects:
            return image
        v = self.data.qvel[self._root_dof : self._root_dof + 2]
        return self._conditions.camera_image(image, math.hypot(v[0], v[1]),
                                             float(self.data.qvel[self._root_dof + 5]))

    # ------------------------------------------------------------------ conditions
    @property
    def conditions(self) -> Conditions:
        """The conditions of the current episode (:class:`envs.conditions.Conditions`)."""
        return self._conditions.current

    @property
    def randomised_conditions(self) -> bool:
        """Whether every episode draws its own conditions (``conditions="random"``, or a
        fixed look with ``"camera": "random"``)."""
        return self._conditions.spec.varies

    @property
    def traffic(self) -> Any:
        """The vehicles and pedestrians (:class:`envs.traffic.Traffic`), or None."""
        return self._conditions.traffic

    def set_conditions(self, conditions: Conditions | None = None) -> Conditions:
        """Change the look now: ``conditions`` (a :class:`~envs.conditions.Conditions`), or
        the next draw of the env's conditions (a new random look for ``conditions="random"``,
        from the episode's stream). Traffic is spawned anew away from the robot. Call after
        ``reset``; returns the conditions applied.

        Raises
        ------
        ValueError
            If the env was made without conditions, or ``conditions`` needs street lamps or
            more movers than the env was made with.
        """
        rt = self._conditions
        if conditions is None:
            rt.draw(self.data, [self._camera], self.pose[:2])
        else:
            rt.apply(conditions, self.data, [self._camera], self.pose[:2])
        mujoco.mj_forward(self.model, self.data)
        return rt.current

    # ------------------------------------------------------------------ helpers
    def _sync_kinematics(self) -> None:
        """Bring body and camera frames to the final qpos (mj_step leaves them one substep behind)."""
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)

    def _obs(self) -> Obs:
        return {"image": self.render_camera(), "goal": self._goal.astype(np.float32)}

    def _info(self, collided_with: tuple[str, ...], control: NDArray[np.float64],
              pose: NDArray[np.float64] | None = None) -> dict[str, Any]:
        pose = self.pose if pose is None else pose
        info = {
            "pose": pose,
            "collision": bool(collided_with),
            "collision_with": collided_with,
            "tipped_over": self.tilt > TIPPED_OVER_TILT,
            "distance_to_goal": math.hypot(pose[0] - self._goal[0], pose[1] - self._goal[1]),
            "control": np.asarray(control, dtype=np.float64),
            "conditions": dict(self._conditions.info),
        }
        if isinstance(self.city, LookalikeCity):
            info["twins"] = self.city.twins(pose)
        return info

    def _distance_to_goal(self) -> float:
        x, y, _ = self.pose
        return math.hypot(x - self._goal[0], y - self._goal[1])

    def _wheel_speeds(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        v, w = u.tolist()
        q = np.array([(v - w * HALF_TRACK) / WHEEL_RADIUS, (v + w * HALF_TRACK) / WHEEL_RADIUS])  # left, right
        if self.motion_noise > 0:
            e = self.np_random.standard_normal(4)
            q = q * (1.0 + self.motion_noise * e[:2]) + self.motion_noise * self.ADDITIVE_WHEEL_NOISE * e[2:]
        return q

    def _check_action(self, action: ArrayLike) -> NDArray[np.float64]:
        v, w = check_array(action, "action", shape=(2,), what="[v, w]").tolist()
        return np.array([min(max(v, -self.V_MAX), self.V_MAX), min(max(w, -self.W_MAX), self.W_MAX)])

    def _check_point(self, value: ArrayLike, dim: int, what: str, margin: float) -> NDArray[np.float64]:
        p = check_array(value, f'options["{what}"]', shape=(dim,),
                        what="[x, y, yaw]" if dim == 3 else "[x, y]").copy()
        lo, hi = self.city.bounds
        if not (lo + margin <= p[0] <= hi - margin and lo + margin <= p[1] <= hi - margin):
            raise ValueError(f'options["{what}"] {p[:2]} is outside the city [{lo}, {hi}]^2 (margin {margin} m)')
        if not self.city.is_free(p[0], p[1], margin):
            raise ValueError(f'options["{what}"] {p[:2]} is inside a building (needs {margin} m clearance)')
        if dim == 3:
            p[2] = wrap_angle(p[2])
        return p

    def _random_goal(self, start: NDArray[np.float64]) -> NDArray[np.float64]:
        for _ in range(1000):
            g = self.city.random_street_point(self.np_random)
            if np.hypot(*(g - start)) >= self.MIN_GOAL_DISTANCE:
                return g
        return g


def make_appearance_nav(**kwargs: Any) -> AppearanceNavEnv:
    """``AppearanceNavEnv(**kwargs)``: the entry point of ``AppearanceNav-v0``.

    A function rather than the class, so ``gymnasium.make(..., render_mode="human")`` reaches
    the constructor's check (a ``ValueError`` naming ``render_mode``) instead of being wrapped
    silently in a ``HumanRendering`` window this headless env cannot open.
    """
    return AppearanceNavEnv(**kwargs)
