"""Scripted agent and navigation features on hand-made belief observations."""

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the env)
from agents.observations import NavigationFeatures, to_body_frame
from agents.scripted import (
    LOOK_TOLERANCE,
    ScriptedAgent,
    check_belief_observation,
    pure_pursuit,
    street_axis,
)
from localization.geometry import wrap_angle

TINY_COV = np.array([1e-4, 0, 0, 1e-4, 0, 1e-4])


def _belief(pose, goal, cov=TINY_COV):
    return {"pose_mean": np.asarray(pose, np.float32), "pose_cov": np.asarray(cov, np.float32),
            "goal": np.asarray(goal, np.float32)}


def _drive_to_goals(plan: str, episodes: int = 8) -> tuple[int, int, list[float]]:
    """(successes, collisions, distance driven per episode) of the agent on the true pose."""
    env = gym.make("AppearanceNav-v0", scene_seed=0, motion_noise=0.05, max_episode_steps=500)
    agent = ScriptedAgent(env.unwrapped.city, plan=plan)
    successes, collisions, lengths = 0, 0, []
    for ep in range(episodes):
        obs, info = env.reset(seed=100 + ep)
        agent.reset()
        xy, length = info["pose"][:2], 0.0
        for _ in range(500):
            action = agent.act(_belief(info["pose"], obs["goal"]))
            assert action.dtype == np.float32 and env.action_space.contains(action)
            obs, _, terminated, truncated, info = env.step(action)
            length += float(np.hypot(*(info["pose"][:2] - xy)))
            xy = info["pose"][:2]
            collisions += info["collision"]
            if terminated or truncated:
                break
        successes += terminated
        lengths.append(length)
    env.close()
    return successes, collisions, lengths


def test_scripted_agent_reaches_goals_on_the_true_pose():
    successes, collisions, _ = _drive_to_goals("drive")
    assert successes == 8
    assert collisions == 0


def test_shortest_plans_turn_on_the_spot_and_drive_no_farther():
    """plan="shortest" (U-turns and turns on the spot, for localizers trained off the lanes)
    reaches the same goals without collisions on a path no longer than the car-like plan's."""
    successes, collisions, shortest = _drive_to_goals("shortest")
    _, _, drive = _drive_to_goals("drive")
    assert successes == 8
    assert collisions == 0
    assert sum(shortest) <= sum(drive)  # measured 136.5 m against 137.1 m over 8 episodes


def test_missing_belief_keys_name_the_problem():
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    obs, _ = env.reset(seed=0)
    agent = ScriptedAgent(env.unwrapped.city)
    with pytest.raises(ValueError, match=r"lacks the belief keys \['pose_mean', 'pose_cov'\]"):
        agent.act(obs)
    with pytest.raises(TypeError, match="belief observation dict"):
        agent.act(np.zeros(3))
    env.close()


@pytest.mark.parametrize("key, value, match", [
    ("pose_mean", np.zeros(2), r"shape \(3,\)"),
    ("pose_cov", np.zeros(3), r"shape \(6,\)"),
    ("goal", np.array([np.nan, 0.0]), "NaN"),
])
def test_bad_belief_values(key, value, match):
    obs = _belief([0, 0, 0], [3, 3])
    obs[key] = value
    with pytest.raises(ValueError, match=match):
        check_belief_observation(obs)


def test_pure_pursuit_turns_in_place_then_drives():
    pose = np.array([0.0, 0.0, 0.0])
    v, w = pure_pursuit(pose, np.array([-1.0, 0.1]), 5.0, 0.9, 1.0, 0.6)
    assert v == 0.0 and w == 1.0  # target behind, on the left
    v, w = pure_pursuit(pose, np.array([1.0, -0.1]), 5.0, 0.9, 1.0, 0.6)
    assert v > 0.8 and w < 0
    v, _ = pure_pursuit(pose, np.array([0.1, 0.0]), 0.1, 0.9, 1.0, 0.6)
    assert v < 0.6  # slows down near the goal


def test_body_frame_and_navigation_features():
    np.testing.assert_allclose(to_body_frame(np.array([[1.0, 1.0]]), np.array([1.0, 0.0, np.pi / 2])),
                               [[1.0, 0.0]], atol=1e-12)
    city = gym.make("AppearanceNav-v0", scene_seed=0).unwrapped.city
    nav = NavigationFeatures(city)
    c = city.street_centers
    cov = np.array([0.04, 0.0, 0.0, 0.09, 0.0, 0.01])
    out = nav(_belief([c[0], c[0], 0.0], [c[0] + 3.0, c[0]], cov))
    assert nav.observation_space.contains(out)
    np.testing.assert_allclose(out["waypoints"], [0.25, 0, 0.5, 0, 1.0, 0], atol=1e-6)
    np.testing.assert_allclose(out["goal"], [0.3, 0.0], atol=1e-6)
    np.testing.assert_allclose(out["uncertainty"], [0.2, 0.3, 0.1], atol=1e-6)


def test_agent_backs_off_after_a_contact_then_steers_again() -> None:
    """A contact: reverse ``back_off_steps`` steps, then the plan again; still in contact after
    two steps of reversing: forward instead."""
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    agent = ScriptedAgent(env.unwrapped.city, back_off_steps=3, back_off_speed=0.2)
    obs, info = env.reset(seed=3)
    env.close()
    belief = _belief(info["pose"], obs["goal"])
    steer = agent.act(belief, {"collision": False})
    backing = [agent.act(belief, {"collision": k == 0}) for k in range(4)]
    for u in backing[:3]:
        np.testing.assert_array_equal(u, np.array([-0.2, 0.0], np.float32))
    np.testing.assert_array_equal(backing[3], steer)  # three steps, then the plan again
    agent.act(belief, {"collision": True})
    agent.reset()  # a new episode does not inherit the reversing
    np.testing.assert_array_equal(agent.act(belief), steer)
    # a contact that lasts while reversing: the obstacle is behind, back off forward
    agent = ScriptedAgent(env.unwrapped.city, back_off_steps=4, back_off_speed=0.2)
    pressed = [agent.act(belief, {"collision": True})[0] for _ in range(5)]
    assert pressed == pytest.approx([-0.2, -0.2, 0.2, 0.2, 0.2]), pressed  # 2 steps back
    with pytest.raises(ValueError, match="back_off_steps"):
        ScriptedAgent(env.unwrapped.city, back_off_steps=-1)


def test_agent_does_not_steer_on_a_lost_belief() -> None:
    """ "lost": stop and turn in place to look; "doubtful" and the like: the same steering at
    the slow factor; "tracking" (or no info): full speed."""
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    agent = ScriptedAgent(env.unwrapped.city, look_rate=0.5, slow_factor=0.5)
    obs, info = env.reset(seed=3)
    env.close()
    pose = info["pose"].copy()
    agent.act(_belief(pose, obs["goal"]))  # plans; then face the carrot: no turn on the spot
    carrot = agent.navigator.path.ahead(agent.lookahead)
    pose[2] = np.arctan2(carrot[1] - pose[1], carrot[0] - pose[0])
    belief = _belief(pose, obs["goal"])
    tracking = agent.act(belief, {"belief_status": "tracking"})
    assert np.array_equal(tracking, agent.act(belief))
    assert tracking[0] > 0
    lost = agent.act(belief, {"belief_status": "lost"})
    to_axis = float(wrap_angle(street_axis(pose[2]) - pose[2]))  # then looks (next test)
    turn = 0.0 if abs(to_axis) <= LOOK_TOLERANCE else np.copysign(0.5, to_axis)
    np.testing.assert_allclose(lost, [0.0, turn])
    for status in ("doubtful", "relocalizing", "ambiguous"):
        slow = agent.act(belief, {"belief_status": status})
        assert slow[0] == pytest.approx(0.5 * tracking[0]) and slow[1] == pytest.approx(tracking[1])


def test_slow_steps_bound_each_stretch_of_a_slow_status() -> None:
    """``slow_steps=3``: the first three steps of a slow stretch at the slow factor, then full
    speed; a step of another status ends the stretch (lost counts, a recovering step too);
    reset starts afresh. None (the default) slows for as long as the status lasts."""
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    obs, info = env.reset(seed=3)
    env.close()
    city = env.unwrapped.city
    agent = ScriptedAgent(city, slow_factor=0.5, slow_steps=3, back_off_steps=1)
    pose = info["pose"].copy()
    agent.act(_belief(pose, obs["goal"]))  # plans; then face the carrot: no turn on the spot
    carrot = agent.navigator.path.ahead(agent.lookahead)
    pose[2] = np.arctan2(carrot[1] - pose[1], carrot[0] - pose[0])
    belief = _belief(pose, obs["goal"])
    full = agent.act(belief, {"belief_status": "tracking"})[0]
    assert full > 0

    def speeds(statuses: list[str]) -> list[float]:
        return [float(agent.act(belief, {"belief_status": s})[0]) for s in statuses]

    doubt = speeds(["doubtful", "relocalizing", "doubtful", "doubtful", "ambiguous"])
    assert doubt == pytest.approx([0.5 * full] * 3 + [full] * 2)
    assert speeds(["tracking", "doubtful", "doubtful"]) == pytest.approx(
        [full, 0.5 * full, 0.5 * full])
    agent.act(belief, {"belief_status": "lost"})  # a look around ends the stretch too
    assert speeds(["doubtful"]) == pytest.approx([0.5 * full])
    assert agent.act(belief, {"belief_status": "doubtful", "collision": True})[0] < 0  # counted
    assert speeds(["doubtful", "doubtful"]) == pytest.approx([0.5 * full, full])
    agent.reset()
    assert speeds(["doubtful"]) == pytest.approx([0.5 * full])
    unbounded = ScriptedAgent(city, slow_factor=0.5)
    assert [float(unbounded.act(belief, {"belief_status": "doubtful"})[0])
            for _ in range(50)] == pytest.approx([0.5 * full] * 50)
    for bad, error in ((0, ValueError), (-2, ValueError), (2.5, TypeError), (True, TypeError)):
        with pytest.raises(error, match="slow_steps"):
            ScriptedAgent(city, slow_steps=bad)


def test_a_lost_agent_turns_to_the_street_axes_and_looks_along_each() -> None:
    """ "lost": turn on the spot the short way to the street axis nearest the believed
    heading, stop there ``look_dwell`` steps, then a quarter turn on to the next axis; a
    status that is not "lost" ends the look (the next one starts at the nearest axis)."""
    env = gym.make("AppearanceNav-v0", scene_seed=0)
    agent = ScriptedAgent(env.unwrapped.city, look_rate=0.5, look_dwell=3)
    obs, info = env.reset(seed=3)
    env.close()
    lost = {"belief_status": "lost"}
    pose = info["pose"].copy()

    def act(yaw: float, status: dict | None = lost) -> np.ndarray:
        pose[2] = yaw
        return agent.act(_belief(pose, obs["goal"]), status)

    np.testing.assert_array_equal(act(0.3), [0.0, -0.5])  # axis 0 is 0.3 rad clockwise
    np.testing.assert_array_equal(act(0.1), [0.0, -0.5])
    for _ in range(3):
        np.testing.assert_array_equal(act(0.01), [0.0, 0.0])  # looks along the street
    np.testing.assert_array_equal(act(0.01), [0.0, 0.5])  # on to pi / 2
    np.testing.assert_array_equal(act(1.2), [0.0, 0.5])
    np.testing.assert_array_equal(act(1.56), [0.0, 0.0])
    act(1.56, {"belief_status": "tracking"})
    np.testing.assert_array_equal(act(-3.0), [0.0, -0.5])  # nearest axis: -pi, the short way
    with pytest.raises(ValueError, match="look_dwell"):
        ScriptedAgent(env.unwrapped.city, look_dwell=-1)
