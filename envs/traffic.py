"""Moving vehicles and pedestrians on the city's streets: occluders and collision hazards.

Each mover is a kinematic MuJoCo mocap body (a box vehicle or a capsule pedestrian) that
follows a random street tour (:func:`envs.lanes.street_tour`): vehicles in the right-hand
lane ``VEHICLE_LANE`` m from the centre line, pedestrians along the street edge
``PEDESTRIAN_LANE`` m from it, on either side. They collide with the robot (it is pushed;
a contact sensor per mover reports the hit, so ``info["collision"]`` is True), never with
the buildings or each other. A mover waits while the robot stands right in its way, but for
``MAX_WAIT`` seconds at most (a robot pushing against a waiting car would otherwise stay stuck
for ever): then it drives on, shoving the robot aside. So the robot is hit when it drives into
a mover, when a mover turns into it, or when it blocks one for too long.

Movers are spawned at reset from the env's conditions stream: never within
``SPAWN_CLEARANCE`` m of the robot's footprint (nor of another mover); a mover with no such
place within ``SPAWN_TRIES`` tours stays parked (out of sight, under the ground). The model
holds as many movers as the conditions can ask for (:func:`traffic_xml`); unused ones are
parked and fully transparent (MuJoCo does not draw them).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from envs.lanes import street_tour
from envs.robot import ROBOT_RADIUS

__all__ = ["PEDESTRIAN_LANE", "SPAWN_CLEARANCE", "VEHICLE_LANE", "Traffic", "traffic_xml"]

VEHICLE_HALF = (0.4, 0.2, 0.24)  # half length, width, height (m)
PEDESTRIAN_SIZE = (0.1, 0.25)  # capsule radius, half length of its cylinder (m)
VEHICLE_LANE = 0.5  # m right of the street centre line
PEDESTRIAN_LANE = 0.82  # m from the centre line (either side)
VEHICLE_SPEED = (0.5, 1.0)  # m/s
PEDESTRIAN_SPEED = (0.2, 0.45)  # m/s
SPAWN_CLEARANCE = 0.5  # m between the robot's footprint disc and a mover's
SPAWN_TRIES = 200
MAX_WAIT = 3.0  # s a mover waits for the robot to get out of its way
TOUR_LENGTH = 600.0  # m: 10 minutes at 1 m/s; a mover stops at the end of its tour
PATH_STEP = 0.05  # m between the resampled points of a tour
_SAMPLES = round(TOUR_LENGTH / PATH_STEP) + 1
_PARKED = (0.0, 0.0, -30.0)


def _radius(kind: int) -> float:
    """Footprint disc radius of a vehicle (0) or a pedestrian (1)."""
    return float(np.hypot(*VEHICLE_HALF[:2])) if kind == 0 else PEDESTRIAN_SIZE[0]


def traffic_xml(n_vehicles: int, n_pedestrians: int) -> tuple[str, str]:
    """(bodies, sensors) XML of ``n_vehicles`` + ``n_pedestrians`` parked movers."""
    bodies, sensors = [], []
    for i in range(n_vehicles + n_pedestrians):
        if i < n_vehicles:
            geom = f'type="box" size="{VEHICLE_HALF[0]} {VEHICLE_HALF[1]} {VEHICLE_HALF[2]}"'
        else:
            geom = f'type="capsule" size="{PEDESTRIAN_SIZE[0]} {PEDESTRIAN_SIZE[1]}"'
        bodies.append(f'<body name="mover{i}" mocap="true" pos="{" ".join(map(str, _PARKED))}">'
                      f'<geom name="mover{i}" {geom} rgba="0.5 0.5 0.5 0" contype="2" '
                      'conaffinity="2" group="2"/></body>')
        sensors.append(f'<contact name="hit{i}" subtree1="robot" body2="mover{i}" num="1" '
                       'data="found"/>')
    return "\n".join(bodies), "\n".join(sensors)


def _offset_path(nodes: NDArray[np.float64], offset: float) -> NDArray[np.float64]:
    """The polyline ``nodes`` (p, 2) shifted ``offset`` m to its right (mitred corners)."""
    d = np.diff(nodes, axis=0)
    d /= np.hypot(*d.T)[:, None]
    n = np.stack([d[:, 1], -d[:, 0]], axis=1)  # right-hand normals of the segments
    n_in = np.vstack([n[:1], n])
    n_out = np.vstack([n, n[-1:]])
    miter = (n_in + n_out) / (1.0 + np.sum(n_in * n_out, axis=1))[:, None]
    return nodes + offset * miter


def _resample(path: NDArray[np.float64]) -> NDArray[np.float64]:
    """The first ``TOUR_LENGTH`` m of the polyline ``path``, one point every ``PATH_STEP`` m."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    s = np.linspace(0.0, TOUR_LENGTH, _SAMPLES)
    return np.column_stack([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])])


class Traffic:
    """The movers of one model (see the module docstring).

    Parameters
    ----------
    model : mujoco.MjModel — compiled with :func:`traffic_xml` (``n_vehicles`` first).
    city : envs.scene.City
    n_vehicles, n_pedestrians : int — the movers the model holds.
    """

    def __init__(self, model: mujoco.MjModel, city: Any, n_vehicles: int,
                 n_pedestrians: int) -> None:
        self.city = city
        n = n_vehicles + n_pedestrians
        self.kind = np.array([0] * n_vehicles + [1] * n_pedestrians)
        body = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"mover{i}") for i in range(n)]
        self._mocap = np.array([model.body_mocapid[b] for b in body], dtype=int)
        self.geom_ids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"mover{i}")
                                  for i in range(n)], dtype=int)
        sensors = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"hit{i}") for i in range(n)]
        self._hit_adr = np.array([model.sensor_adr[s] for s in sensors], dtype=int)
        self._model = model
        self.active = np.zeros(n, dtype=bool)
        self._paths = np.zeros((n, _SAMPLES, 2))  # tours resampled every PATH_STEP metres
        self.s = np.zeros(n)  # arc length travelled (m)
        self.speed = np.zeros(n)
        self.waited = np.zeros(n)  # seconds waited in a row for the robot
        self.poses = np.zeros((n, 3))
        self._z = np.where(self.kind == 0, VEHICLE_HALF[2], sum(PEDESTRIAN_SIZE)) + 0.01
        self._half = np.array([VEHICLE_HALF[:2] if k == 0 else (PEDESTRIAN_SIZE[0],) * 2
                               for k in self.kind]).reshape(n, 2)

    def __len__(self) -> int:
        return len(self.kind)

    def spawn(self, data: mujoco.MjData, rng: np.random.Generator, robot_xy: NDArray[np.float64],
              n_vehicles: int, n_pedestrians: int) -> None:
        """Park every mover, then place ``n_vehicles`` vehicles and ``n_pedestrians``
        pedestrians (at most what the model holds) away from the robot and each other."""
        self.active[:] = False
        self.waited[:] = 0.0
        self._model.geom_rgba[self.geom_ids, 3] = 0.0
        data.mocap_pos[self._mocap] = _PARKED
        want = {0: n_vehicles, 1: n_pedestrians}
        for i in range(len(self)):
            k = int(self.kind[i])
            if want[k] <= 0:
                continue
            want[k] -= 1
            if self._place(i, rng, robot_xy):
                self.active[i] = True
                self._model.geom_rgba[self.geom_ids[i]] = (*rng.uniform(0.1, 0.95, 3), 1.0)
        self._write(data)

    def _place(self, i: int, rng: np.random.Generator, robot_xy: NDArray[np.float64]) -> bool:
        k = int(self.kind[i])
        r = _radius(k)
        for _ in range(SPAWN_TRIES):
            lane = VEHICLE_LANE if k == 0 else PEDESTRIAN_LANE * rng.choice([-1.0, 1.0])
            path = _resample(_offset_path(street_tour(self.city, TOUR_LENGTH + 1.0, rng), lane))
            s = rng.uniform(0.0, 6.0)
            xy = path[round(s / PATH_STEP)]
            if np.hypot(*(xy - robot_xy)) < ROBOT_RADIUS + r + SPAWN_CLEARANCE:
                continue
            others = self.active.nonzero()[0]
            gaps = np.hypot(*(self.poses[others, :2] - xy).T) - [_radius(int(self.kind[j]))
                                                                 for j in others]
            if len(others) and gaps.min() < r + 0.3:
                continue
            self._paths[i], self.s[i] = path, s
            self.speed[i] = rng.uniform(*(VEHICLE_SPEED if k == 0 else PEDESTRIAN_SPEED))
            self.poses[i] = self._pose_at(np.array([i]))[0]
            return True
        return False

    def _pose_at(self, idx: NDArray[np.int_]) -> NDArray[np.float64]:
        """Poses (k, 3) of movers ``idx`` at their arc lengths ``s``."""
        j = np.minimum(self.s[idx] / PATH_STEP, _SAMPLES - 1.0)
        j0 = np.minimum(j.astype(int), _SAMPLES - 2)
        t = (j - j0)[:, None]
        paths = self._paths  # indexed in place: a copy of the tours would cost more than the rest
        xy = (1 - t) * paths[idx, j0] + t * paths[idx, j0 + 1]
        ahead = paths[idx, np.minimum(j0 + 5, _SAMPLES - 1)] - paths[idx, np.maximum(j0 - 5, 0)]
        return np.column_stack([xy, np.arctan2(ahead[:, 1], ahead[:, 0])])

    def advance(self, data: mujoco.MjData, dt: float, robot_xy: NDArray[np.float64]) -> None:
        """Move every active mover ``dt`` seconds along its tour (waiting while the robot
        stands right ahead of it) and write the mocap poses."""
        idx = self.active.nonzero()[0]
        if not len(idx):
            return
        x, y, yaw = self.poses[idx].T
        c, s = np.cos(yaw), np.sin(yaw)
        rx, ry = robot_xy[0] - x, robot_xy[1] - y
        fwd, lat = rx * c + ry * s, -rx * s + ry * c
        half = self._half[idx]
        blocked = (fwd > 0) & (fwd < half[:, 0] + ROBOT_RADIUS + 0.4) & \
            (np.abs(lat) < half[:, 1] + ROBOT_RADIUS + 0.1)
        wait = blocked & (self.waited[idx] < MAX_WAIT)
        self.waited[idx] = np.where(blocked, self.waited[idx] + dt, 0.0)
        self.s[idx] = np.where(wait, self.s[idx], np.minimum(self.s[idx] + self.speed[idx] * dt,
                                                             TOUR_LENGTH))
        self.poses[idx] = self._pose_at(idx)
        self._write(data)

    def _write(self, data: mujoco.MjData) -> None:
        idx = self.active.nonzero()[0]
        if not len(idx):
            return
        x, y, yaw = self.poses[idx].T
        m = self._mocap[idx]
        data.mocap_pos[m] = np.column_stack([x, y, self._z[idx]])
        data.mocap_quat[m] = np.column_stack([np.cos(yaw / 2), np.zeros_like(x), np.zeros_like(x),
                                              np.sin(yaw / 2)])

    def hit(self, data: mujoco.MjData) -> bool:
        """Whether the robot touches a mover (the contact sensors, at the last physics step)."""
        return bool(len(self._hit_adr) and np.any(data.sensordata[self._hit_adr] > 0))

    def active_poses(self) -> NDArray[np.float64]:
        """(k, 3) ``[x, y, yaw]`` of the movers on the streets."""
        return self.poses[self.active].copy()

    def footprint_radii(self) -> NDArray[np.float64]:
        """(k,) footprint disc radii of the movers on the streets."""
        return np.array([_radius(int(k)) for k in self.kind[self.active]])
