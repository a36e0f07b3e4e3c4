"""How fast the robot really turns: its yaw rate for a commanded U = [v, w].

The known motion model (:mod:`envs.motion_model`) takes the commanded U as the robot's
velocity. The robot is a differential drive in MuJoCo (:mod:`envs.robot`): its wheels grip
and scrub, and on the spot a commanded turn meets the tyres' friction. Measured in steady
state (:func:`measure_turn_response`), it turns at 0.08 / 0.26 / 0.45 / 0.65 / 0.85 rad/s
on the spot for 0.2 / 0.4 / 0.6 / 0.8 / 1.0 commanded (a dead zone of about 0.15 rad/s),
and at 0.93-0.96 of the command while driving at 0.3-0.6 m/s (forward speed: 0.95 of v).

A belief that predicts with the commanded w turns about 1.4 times as far as the robot while
it turns on the spot to look around; then every image is off the maps and nothing brings the
belief back (docs/benchmarks.md §10, stop 64). :data:`ROBOT_TURN_RESPONSE` is the measured
yaw rate on a grid of commands, and ``BeliefFilter(turn_response=...)`` predicts with it
(opt-in: a steady state misreads curves driven with a w that changes every step, method §13.6).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import RegularGridInterpolator

from localization._validation import check_array

__all__ = ["ROBOT_TURN_RESPONSE", "TurnResponse", "measure_turn_response", "turn_response_for"]

#: commanded forward speeds (m/s) and turn rates (rad/s, >= 0) of the packaged table
SPEEDS = tuple(round(-0.6 + 0.1 * i, 1) for i in range(13))
TURN_RATES = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
#: the robot's steady yaw rate (rad/s) for each speed (rows) and turn rate (columns):
#: ``measure_turn_response`` on city 53 (a tuning city) from its reset pose of seed 1
_ROBOT_TABLE = (
    (0.0000, 0.0998, 0.2698, 0.5513, 0.7198, 0.9208),  # v = -0.6
    (0.0000, 0.1051, 0.2962, 0.5621, 0.7289, 0.9224),  # v = -0.5
    (0.0000, 0.1290, 0.3453, 0.5671, 0.7394, 0.9409),  # v = -0.4
    (0.0000, 0.1407, 0.3660, 0.5702, 0.7463, 0.9439),  # v = -0.3
    (0.0000, 0.1408, 0.3666, 0.5599, 0.7356, 0.9283),  # v = -0.2
    (0.0000, 0.1338, 0.3557, 0.5283, 0.7043, 0.8921),  # v = -0.1
    (0.0000, 0.0837, 0.2586, 0.4455, 0.6528, 0.8483),  # v = +0.0
    (0.0000, 0.1546, 0.3244, 0.5022, 0.6773, 0.8629),  # v = +0.1
    (0.0000, 0.2004, 0.3779, 0.5409, 0.7118, 0.9040),  # v = +0.2
    (0.0000, 0.2169, 0.3913, 0.5529, 0.7344, 0.9305),  # v = +0.3
    (0.0000, 0.2220, 0.3973, 0.5594, 0.7483, 0.9444),  # v = +0.4
    (0.0000, 0.2221, 0.3987, 0.5628, 0.7585, 0.9543),  # v = +0.5
    (0.0000, 0.2261, 0.4009, 0.5664, 0.7658, 0.9620),  # v = +0.6
)


class TurnResponse:
    """The yaw rate a robot turns at for a command U = [v, w]: a table over commanded
    speeds and turn rates, bilinear in between, odd in w, held at the table's edge beyond.

    Parameters
    ----------
    speeds : array (n_v,) — increasing commanded speeds (m/s).
    turn_rates : array (n_w,) — increasing commanded turn rates (rad/s), the first 0.
    yaw_rates : array (n_v, n_w) — the robot's yaw rate (rad/s) for each pair.
    """

    def __init__(self, speeds: ArrayLike, turn_rates: ArrayLike, yaw_rates: ArrayLike) -> None:
        v = check_array(speeds, "speeds", ndim=1, what="commanded speeds")
        w = check_array(turn_rates, "turn_rates", ndim=1, what="commanded turn rates")
        table = check_array(yaw_rates, "yaw_rates", shape=(len(v), len(w)),
                            what="yaw rates per (speed, turn rate)")
        for name, grid in (("speeds", v), ("turn_rates", w)):
            if len(grid) < 2 or np.any(np.diff(grid) <= 0):
                raise ValueError(f"{name} must be at least two increasing values")
        if w[0] != 0.0:
            raise ValueError(f"turn_rates must start at 0 (the table is odd in w), got {w[0]}")
        self.speeds, self.turn_rates, self.yaw_rates = v, w, table
        self._table = RegularGridInterpolator((v, w), table)

    def __repr__(self) -> str:
        return (f"TurnResponse({len(self.speeds)} speeds {self.speeds[0]:g}..{self.speeds[-1]:g}"
                f" m/s x {len(self.turn_rates)} turn rates 0..{self.turn_rates[-1]:g} rad/s)")

    def __call__(self, u: ArrayLike) -> float:
        """The yaw rate (rad/s) for the command ``u`` = [v, w] (2,)."""
        v, w = check_array(u, "u", shape=(2,), what="[v, w] (the control)").tolist()
        q = [[min(max(v, self.speeds[0]), self.speeds[-1]),
              min(abs(w), self.turn_rates[-1])]]
        return float(np.copysign(self._table(q)[0], w))


def measure_turn_response(env: Any, pose: ArrayLike, speeds: ArrayLike = SPEEDS,
                          turn_rates: ArrayLike = TURN_RATES, steps: int = 30,
                          settle: int = 8) -> TurnResponse:
    """Measure ``env``'s robot: from ``pose`` (3,), hold each command for ``steps`` steps
    and average the yaw rate after the first ``settle``; odd in w (the mean of +w and -w,
    which cancels a drift of the pose's own). The robot needs room around ``pose`` (at
    0.6 m/s it drives about 2 m); a contact raises a ValueError naming ``pose``."""
    check_array(pose, "pose", shape=(3,), what="[x, y, yaw]")
    table = np.array([[_yaw_rate(env, pose, v, w, steps, settle) if w else 0.0
                       for w in turn_rates] for v in speeds])
    return TurnResponse(speeds, turn_rates, table)


def _yaw_rate(env: Any, pose: ArrayLike, v: float, w: float, steps: int,
              settle: int) -> float:
    """The steady yaw rate for [v, w], odd in w: the half difference of +w and -w."""
    rates = []
    for sign in (1.0, -1.0):
        _, info = env.reset(options={"pose": np.asarray(pose, dtype=np.float64)})
        yaw = [info["pose"][2]]
        for _ in range(steps):
            _, _, _, _, info = env.step(np.array([v, sign * w], dtype=np.float32))
            if info["collision"]:
                where = [round(float(p), 2) for p in np.asarray(pose)]
                raise ValueError(f"the robot touched the city from pose {where}: "
                                 "measure the response where it has room")
            yaw.append(info["pose"][2])
        rates.append(float(np.mean(np.diff(np.unwrap(yaw))[settle:])) / env.unwrapped.dt)
    return 0.5 * (rates[0] - rates[1])


#: the env's robot (:mod:`envs.robot`), measured as described above
ROBOT_TURN_RESPONSE = TurnResponse(SPEEDS, TURN_RATES, _ROBOT_TABLE)


def turn_response_for(option: object) -> TurnResponse | None:
    """``BeliefFilter(turn_response=...)``: False / None (none), True (the env's robot,
    :data:`ROBOT_TURN_RESPONSE`) or a :class:`TurnResponse`; else a TypeError naming it."""
    if isinstance(option, TurnResponse):
        return option
    if option is None or isinstance(option, (bool, np.bool_)):
        return ROBOT_TURN_RESPONSE if option else None
    raise TypeError(f"turn_response must be a bool or a TurnResponse, got {type(option).__name__}")
