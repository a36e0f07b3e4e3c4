"""The differential-drive robot: MJCF snippets and its geometry constants.

Two hinge-jointed driven wheels (velocity actuators) and a frictionless caster
sphere under a box chassis (plus a front caster 1 cm off the ground that stops
the robot tipping forward when braking), on a free joint (kept on its wheels by
:mod:`envs.upright`). The camera ``"ego"`` sits on a
mast above the front axle, looking along the robot's heading (+x of the body):
MuJoCo cameras look along their local -z with y up, hence ``xyaxes="0 -1 0 0 0 1"``.
The robot's geoms are in geom group 3, which cameras do not draw by default: the
robot never sees itself and costs no draw calls.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

WHEEL_RADIUS = 0.05  # m
HALF_TRACK = 0.13  # m, wheel centre to robot centre along the axle
ROBOT_RADIUS = 0.22  # m, a disc covering the robot footprint
CAMERA_HEIGHT = 0.40  # m above the ground
CAMERA_FOVY = 75.0  # degrees
MAX_WHEEL_SPEED = 40.0  # rad/s, actuator ctrlrange
WHEEL_KV = 0.3  # N m s, velocity-servo gain
MAX_WHEEL_TORQUE = 0.6  # N m

ROBOT_XML = f"""
    <body name="robot" pos="0 0 {WHEEL_RADIUS}">
      <freejoint name="root"/>
      <geom name="chassis" type="box" pos="-0.03 0 0.03" size="0.16 0.1 0.04" rgba="0.9 0.9 0.9 1"
            mass="2.0" contype="2" conaffinity="2" group="3"/>
      <geom name="mast" type="cylinder" pos="0.08 0 0.18" size="0.015 0.12" rgba="0.2 0.2 0.2 1"
            mass="0.05" contype="0" conaffinity="0" group="3"/>
      <geom name="caster" type="sphere" pos="-0.14 0 -0.025" size="0.025" condim="1" mass="0.05"
            rgba="0.2 0.2 0.2 1" contype="1" conaffinity="1" group="3"/>
      <geom name="caster_front" type="sphere" pos="0.1 0 -0.015" size="0.025" condim="1" mass="0.05"
            rgba="0.2 0.2 0.2 1" contype="1" conaffinity="1" group="3"/>
      <camera name="ego" pos="0.1 0 {CAMERA_HEIGHT - WHEEL_RADIUS}" xyaxes="0 -1 0 0 0 1" fovy="{CAMERA_FOVY}"/>
      <body name="wheel_left" pos="0 {HALF_TRACK} 0">
        <joint name="left" type="hinge" axis="0 1 0" armature="0.001" damping="0.001"/>
        <geom name="wheel_left" type="sphere" size="{WHEEL_RADIUS}" mass="0.5"
              friction="1.2 0.01 0.001" rgba="0.1 0.1 0.1 1" contype="3" conaffinity="3" group="3"/>
      </body>
      <body name="wheel_right" pos="0 {-HALF_TRACK} 0">
        <joint name="right" type="hinge" axis="0 1 0" armature="0.001" damping="0.001"/>
        <geom name="wheel_right" type="sphere" size="{WHEEL_RADIUS}" mass="0.5"
              friction="1.2 0.01 0.001" rgba="0.1 0.1 0.1 1" contype="3" conaffinity="3" group="3"/>
      </body>
    </body>
    <body name="goal" mocap="true" pos="0 0 0.01">
      <geom name="goal" type="cylinder" size="0.25 0.005" rgba="0.1 0.9 0.2 0.6" contype="0" conaffinity="0"
            group="4"/>
    </body>
"""

ACTUATOR_XML = f"""
    <velocity name="left" joint="left" kv="{WHEEL_KV}" ctrlrange="{-MAX_WHEEL_SPEED} {MAX_WHEEL_SPEED}"
              forcerange="{-MAX_WHEEL_TORQUE} {MAX_WHEEL_TORQUE}"/>
    <velocity name="right" joint="right" kv="{WHEEL_KV}" ctrlrange="{-MAX_WHEEL_SPEED} {MAX_WHEEL_SPEED}"
              forcerange="{-MAX_WHEEL_TORQUE} {MAX_WHEEL_TORQUE}"/>
"""

ROBOT_GEOMS = ("chassis", "caster", "caster_front", "wheel_left", "wheel_right")

# while any robot geom touches a geom of the static body "city" (buildings, boundary walls):
# the number of contacts, then the centroid (world, m) of their net force, a bump sensor's
# reading of where it was hit (:func:`contact_bearing`)
SENSOR_XML = """
    <contact name="collision" subtree1="robot" body2="city" num="1" data="found pos"
             reduce="netforce"/>
"""


def contact_bearing(sensor: Sequence[float], pose: Sequence[float]) -> float:
    """The bearing (rad, in [-pi, pi], counter-clockwise from the robot's heading) of the
    point where the robot touches the city, from the ``collision`` sensor's reading
    ``[found, x, y, z]`` (the contacts' net-force centroid) and the robot's ``pose``
    ``[x, y, yaw]``: 0 a bump ahead, +-pi one behind (what a ring bumper reports)."""
    angle = math.atan2(sensor[2] - pose[1], sensor[1] - pose[0]) - pose[2]
    return math.remainder(angle, math.tau)

