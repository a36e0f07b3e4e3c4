"""Appearance conditions (envs.conditions, envs.lighting, envs.camera_effects, envs.traffic)."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the env)
from envs.conditions import (
    DEFAULT,
    NO_CAMERA,
    PRESETS,
    Conditions,
    draw_random,
    parse_conditions,
)
from envs.datasets import collect_dataset
from envs.robot import ROBOT_RADIUS
from envs.traffic import SPAWN_CLEARANCE

SIZE = (32, 32)
POSE = [-3.0, -6.5, 1.5708]  # on a street of city 0, looking along it past an intersection


def make(conditions=None, **kw):
    return gym.make("AppearanceNav-v0", image_size=SIZE, conditions=conditions, **kw)


def drive(env, seed=3, steps=6, pose=POSE):
    """Images of a reset at ``pose`` and ``steps`` steps forward while turning."""
    obs, info = env.reset(seed=seed, options={"pose": pose})
    images, infos = [obs["image"]], [info]
    for _ in range(steps):
        obs, _, _, _, info = env.step([0.8, 0.5])
        images.append(obs["image"])
        infos.append(info)
    return np.array(images), infos


def test_default_is_byte_identical_to_todays_images():
    plain, default, none = make(), make("default"), make(None)
    a, _ = drive(plain)
    for env in (default, none):
        b, infos = drive(env)
        assert np.array_equal(a, b)
        assert infos[-1]["conditions"]["holds"] == []
    for env in (plain, default, none):
        env.close()


@pytest.mark.parametrize("name", [p for p in PRESETS if p != "default"])
def test_each_preset_renders_and_differs_from_default(name):
    plain, env = make(), make(name)
    a, _ = drive(plain, steps=25)
    b, infos = drive(env, steps=25)
    assert b.shape == a.shape and b.dtype == np.uint8
    assert not np.array_equal(a, b)
    assert infos[-1]["conditions"]["name"] == name
    assert infos[-1]["conditions"]["holds"]  # it says which conditions hold
    assert [i["pose"].tolist() for i in infos[:1]] == [j["pose"].tolist() for j in _[:1]]
    plain.close()
    env.close()


def test_same_seed_gives_same_conditions_and_images():
    e1, e2 = make("random"), make("random")
    a, ia = drive(e1, seed=11)
    b, ib = drive(e2, seed=11)
    c, ic = drive(e1, seed=11)  # the same env again
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert ia[0]["conditions"] == ib[0]["conditions"] == ic[0]["conditions"]
    e1.close()
    e2.close()


def test_randomisation_changes_with_the_episode_seed_only():
    env = make("random", scene_seed=0)
    looks = {}
    for seed in range(6):
        _, info = env.reset(seed=seed)
        looks[seed] = info["conditions"]
    assert len({str(v) for v in looks.values()}) == 6  # a new seed, a new look
    # ... but neither the pose, the steps, nor the city change it
    _, info = env.reset(seed=4, options={"pose": POSE})
    assert info["conditions"] == looks[4]
    for _ in range(5):
        _, _, _, _, info = env.step([0.5, 0.3])
    assert info["conditions"] == looks[4]
    other = make("random", scene_seed=5)
    assert other.reset(seed=4)[1]["conditions"] == looks[4]
    # the poses and goals come from np_random as without conditions
    plain = make()
    _, p = plain.reset(seed=4)
    _, q = env.reset(seed=4)
    assert np.array_equal(p["pose"], q["pose"]) and np.array_equal(plain.unwrapped.goal,
                                                                   env.unwrapped.goal)
    # seed None continues the stream: each episode differs, and replays from the seed
    env.reset(seed=9)
    first = [env.reset()[1]["conditions"] for _ in range(3)]
    env.reset(seed=9)
    assert [env.reset()[1]["conditions"] for _ in range(3)] == first
    assert first[0] != first[1]
    for e in (env, other, plain):
        e.close()


def test_random_draws_are_valid_conditions():
    rng = np.random.default_rng(0)
    names = set()
    for _ in range(200):
        c = draw_random(rng)
        assert parse_conditions(c).conditions == c  # every field in range
        names.add(c.name)
        assert c.vehicles == c.pedestrians == 0
    assert names == {f"random:{b}" for b in ("default", "dusk", "night", "overcast", "fog")}


def test_dict_conditions_override_a_preset_and_random():
    spec = parse_conditions({"preset": "night", "vehicles": 3, "noise": 0.01})
    assert spec.conditions == dataclasses.replace(PRESETS["night"], vehicles=3, noise=0.01)
    spec = parse_conditions({"preset": "random", "pedestrians": 2})
    assert spec.random and spec.max_pedestrians == 2 and spec.lamps
    assert spec.draw(np.random.default_rng(1)).pedestrians == 2
    assert parse_conditions(None).conditions == DEFAULT


def test_set_conditions_changes_the_look_and_checks_capacity():
    env = make("night")
    env.reset(seed=0, options={"pose": POSE})
    base = env.unwrapped
    night = base.render_camera()
    assert base.set_conditions(DEFAULT) == DEFAULT
    day = base.render_camera()
    assert night.mean() < day.mean()
    with pytest.raises(ValueError, match="vehicles"):
        base.set_conditions(dataclasses.replace(DEFAULT, vehicles=1))
    env.close()
    plain = make()
    plain.reset(seed=0)
    with pytest.raises(ValueError, match="without conditions"):
        plain.unwrapped.set_conditions(PRESETS["dusk"])
    plain.close()


def test_traffic_never_spawns_inside_the_robot():
    env = make({"preset": "traffic", "vehicles": 8, "pedestrians": 8})
    base = env.unwrapped
    for seed in range(40):
        # random poses, and poses at an intersection where every tour passes
        options = {"pose": [-3.0, -3.0, 0.3 * seed]} if seed % 2 else None
        _, info = env.reset(seed=seed, options=options)
        movers = base.traffic.active_poses()
        assert len(movers) >= 12  # nearly all of them found a place
        gaps = np.hypot(*(movers[:, :2] - info["pose"][:2]).T) - base.traffic.footprint_radii()
        assert gaps.min() >= ROBOT_RADIUS + SPAWN_CLEARANCE - 1e-9
        assert not info["collision"]
    env.close()


def test_traffic_moves_and_hits_are_collisions():
    env = make({"preset": "traffic", "vehicles": 1, "pedestrians": 0})
    base = env.unwrapped
    env.reset(seed=2)
    start = base.traffic.active_poses()[0]
    for _ in range(10):
        _, _, _, _, info = env.step([0.0, 0.0])
    moved = base.traffic.active_poses()[0]
    assert np.hypot(*(moved[:2] - start[:2])) > 0.3  # it drives along the streets
    assert not info["collision"]
    # stop it, and drive the robot into its side
    base.traffic.speed[:] = 0.0
    yaw = moved[2]
    side = np.array([-np.sin(yaw), np.cos(yaw)])
    p = moved[:2] + 0.8 * side
    base.set_pose([p[0], p[1], yaw - np.pi / 2])  # a teleport: no new traffic
    hits = []
    for _ in range(15):
        _, _, _, _, info = env.step([1.0, 0.0])
        hits.append(info["collision_with"])
        assert info["collision"] == bool(info["collision_with"])
    assert ("traffic",) in hits  # what it touched is named: the vehicle, not a building
    env.close()


def test_camera_effects_only_change_what_they_should():
    plain, blur = make(), make("motion_blur")
    plain.reset(seed=0, options={"pose": POSE})
    blur.reset(seed=0, options={"pose": POSE})
    # standing still there is no motion blur
    assert np.array_equal(plain.unwrapped.render_camera(), blur.unwrapped.render_camera())
    noisy = make("noise")
    a, _ = drive(noisy, seed=1)
    b, _ = drive(plain, seed=1)
    assert 0 < np.abs(a.astype(int) - b.astype(int)).mean() < 20
    for e in (plain, blur, noisy):
        e.close()


def test_collect_dataset_varies_randomised_conditions_per_sample():
    env = make("random")
    images, poses = collect_dataset(env, 6, "random", seed=0, progress=False)
    again, poses2 = collect_dataset(env, 6, "random", seed=0, progress=False)
    assert np.array_equal(images, again) and np.array_equal(poses, poses2)
    plain = make()
    ref, _ = collect_dataset(plain, 6, "random", seed=0, progress=False)
    means = images.reshape(6, -1).mean(1) - ref.reshape(6, -1).mean(1)
    assert np.ptp(means) > 3  # not one look for all
    env.close()
    plain.close()


def test_conditions_dataclass_info_is_json_able():
    import json

    info = Conditions(name="x", fog=(1.0, 5.0), vehicles=2).to_info()
    assert json.loads(json.dumps(info))["fog"] == [1.0, 5.0]
    assert set(info["holds"]) == {"fog", "vehicles"}


@pytest.mark.parametrize("spec", ["night", "random", {"preset": "random", "vehicles": 3}])
def test_todays_look_in_an_env_built_for_conditions_is_byte_identical(spec):
    """Lamps and movers the model holds for other looks are not drawn in today's look, so a
    daylight localizer sees only the conditions' own changes under any preset."""
    plain, env = make(), make(spec)
    plain.reset(seed=0, options={"pose": POSE})
    env.reset(seed=0, options={"pose": POSE})
    env.unwrapped.set_conditions(DEFAULT)
    assert np.array_equal(plain.unwrapped.render_camera(), env.unwrapped.render_camera())
    plain.close()
    env.close()


def test_a_mover_waits_for_the_robot_then_drives_on():
    from envs.traffic import MAX_WAIT, VEHICLE_HALF

    env = make({"preset": "traffic", "vehicles": 1, "pedestrians": 0})
    base = env.unwrapped
    env.reset(seed=2)
    x, y, yaw = base.traffic.active_poses()[0]
    ahead = VEHICLE_HALF[0] + ROBOT_RADIUS + 0.2
    base.set_pose([x + ahead * np.cos(yaw), y + ahead * np.sin(yaw), yaw])
    s0 = base.traffic.s[0]
    for _ in range(int(MAX_WAIT / base.dt) - 2):
        env.step([0.0, 0.0])
    assert base.traffic.s[0] == s0  # it waits while the robot stands in its way
    hits = [env.step([0.0, 0.0])[4]["collision"] for _ in range(20)]
    assert base.traffic.s[0] > s0 + 0.3  # ... not for ever: it drives on
    assert any(hits)  # shoving the robot aside
    env.close()


def test_a_fixed_look_through_randomised_cameras():
    """{"preset": look, "camera": "random"}: the look's light in every image, each image's
    camera its own draw (draw_camera: none half of the time), the same for the same seed."""
    look = dataclasses.replace(PRESETS["dusk"], noise=0.03)  # its own camera is replaced
    spec = parse_conditions({"preset": look, "camera": "random"})
    assert spec.varies and not spec.random and not spec.is_default
    draws = [spec.draw(np.random.default_rng(s)) for s in range(40)]
    assert {dataclasses.replace(d, **NO_CAMERA) for d in draws} == {
        dataclasses.replace(look, **NO_CAMERA)}
    assert any(d.noise == 0.0 for d in draws) and any(d.noise > 0.0 for d in draws)
    assert parse_conditions({"preset": "default", "camera": "random"}).varies
    assert not parse_conditions({"preset": "dusk"}).varies
    env = make({"preset": look, "camera": "random"})
    images, _ = collect_dataset(env, 8, "random", seed=0, progress=False)
    again, _ = collect_dataset(env, 8, "random", seed=0, progress=False)
    fixed = make(dataclasses.replace(look, **NO_CAMERA))
    plain, _ = collect_dataset(fixed, 8, "random", seed=0, progress=False)
    assert np.array_equal(images, again)
    same = [np.array_equal(a, b) for a, b in zip(images, plain)]
    assert any(same) and not all(same)  # some images without camera effects, some with
    env.close()
    fixed.close()


def test_collect_dataset_shows_a_fresh_envs_look():
    """A fixed look is applied at reset: collecting from an env never reset used to give
    today's daylight images for conditions="dusk" (grid and random modes)."""
    fresh, used, plain = make("dusk"), make("dusk"), make()
    used.reset(seed=5)
    for mode in ("random", "grid"):
        images, _ = collect_dataset(fresh, 3, mode, seed=0, progress=False)
        again, _ = collect_dataset(used, 3, mode, seed=0, progress=False)
        daylight, _ = collect_dataset(plain, 3, mode, seed=0, progress=False)
        assert np.array_equal(images, again)
        assert images.mean() < daylight.mean() - 20  # dusk, not today's light
    for env in (fresh, used, plain):
        env.close()
