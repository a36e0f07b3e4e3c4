"""The image guard: no forward step that the image's own pose estimate says runs into a building."""

import numpy as np
import pytest

from agents.guard import ImageGuard, rollout
from agents.scripted import ScriptedAgent
from envs.robot import ROBOT_RADIUS
from envs.scene import generate_city


@pytest.fixture(scope="module")
def city():
    return generate_city(0)


@pytest.fixture(scope="module")
def facing_wall(city):
    """A pose 0.4 m in front of a building's west face, looking at it (yaw 0)."""
    for x0, y0, x1, y1 in city.footprints():
        pose = np.array([x0 - 0.4, 0.5 * (y0 + y1), 0.0])
        if abs(city.clearance(pose[None, :2])[0] - 0.4) < 1e-9:
            return pose
    raise AssertionError("no building face with 0.4 m of street in front of it")


def test_rollout_straight_and_arc():
    np.testing.assert_allclose(rollout(np.array([1.0, 2.0, np.pi / 2]), np.array([1.0, 0.0]),
                                       2.0, 2), [[1, 3], [1, 4]], atol=1e-12)
    # a quarter circle of radius 1 from the origin heading +x, turning left
    end = rollout(np.zeros(3), np.array([1.0, 1.0]), np.pi / 2, 4)[-1]
    np.testing.assert_allclose(end, [1.0, 1.0], atol=1e-12)


def test_blocks_forward_into_the_wall_only(city, facing_wall):
    guard = ImageGuard(city)
    info = {"image_pose": facing_wall}
    belief = facing_wall + [0.0, 1.3, 0.0]  # the belief 1.3 m off, as after a push
    assert guard.blocks(np.array([0.9, 0.0]), belief, info)
    away = {"image_pose": facing_wall + [0.0, 0.0, np.pi]}
    assert not guard.blocks(np.array([0.9, 0.0]), belief, away)
    assert not guard.blocks(np.array([-0.3, 0.0]), belief, info)  # reversing is not vetoed
    assert not guard.blocks(np.array([0.0, 1.0]), belief, info)  # nor turning on the spot
    assert not guard.blocks(np.array([0.9, 0.0]), belief, None)  # no info: no veto
    with pytest.raises(KeyError, match="image_pose=True"):  # info without it: said, not ignored
        guard.blocks(np.array([0.9, 0.0]), belief, {"belief_status": "tracking"})
    assert not guard.blocks(np.array([0.9, 0.0]), belief, {"image_pose": np.full(3, np.nan)})
    far = facing_wall + [0.0, 4.0, 0.0]  # an aliased image pose is ignored
    assert not guard.blocks(np.array([0.9, 0.0]), far, info)


def test_the_margin_sets_how_far_ahead_a_wall_counts(city, facing_wall):
    """0.4 m from the wall: with a 0.05 m margin a slow step (0.1 m in the horizon) keeps the
    disc off the wall and passes; the default margin (the map's reach) stops it already."""
    assert 0.4 - 0.1 > ROBOT_RADIUS + 0.05
    info, slow = {"image_pose": facing_wall}, np.array([0.2, 0.0])
    assert not ImageGuard(city, margin=0.05).blocks(slow, facing_wall, info)
    assert ImageGuard(city).blocks(slow, facing_wall, info)


def test_scripted_agent_stops_short_of_the_wall(city, facing_wall):
    goal = facing_wall[:2] + [-6.0, 0.0]
    belief = {"pose_mean": facing_wall + [0.0, 0.0, np.pi], "pose_cov": np.ones(6) * 0.01,
              "goal": goal}
    info = {"belief_status": "tracking", "image_pose": facing_wall}
    guarded, plain = ScriptedAgent(city, guard=True), ScriptedAgent(city)
    u_plain = plain.act(belief, info)
    assert u_plain[0] > 0  # the belief faces the goal down the street
    u = guarded.act(belief, info)
    assert u[0] == 0.0 and u[1] == pytest.approx(u_plain[1])
    assert guarded.guard.vetoes == 1
    info["image_pose"] = belief["pose_mean"]  # the image agrees with the belief: no veto
    assert guarded.act(belief, info)[0] > 0


def test_patience_ends_a_veto_that_would_hold_forever(city, facing_wall):
    """A vetoed robot does not move and sends the same command again: without patience the
    veto holds for ever; with ``patience=3, yield_steps=2`` three vetoes, two commands let
    through, then it guards again. A command that passes ends the run of vetoes; reset too."""
    info, u = {"image_pose": facing_wall}, np.array([0.9, 0.0])

    def speeds(guard: ImageGuard, n: int) -> list[float]:
        return [float(guard.filter(u, facing_wall, info)[0]) for _ in range(n)]

    assert speeds(ImageGuard(city), 50) == [0.0] * 50
    guard = ImageGuard(city, patience=3, yield_steps=2)
    assert speeds(guard, 8) == [0.0, 0.0, 0.0, 0.9, 0.9, 0.0, 0.0, 0.0]
    assert guard.vetoes == 6
    away = facing_wall + [0.0, 0.0, np.pi]
    guard = ImageGuard(city, patience=3, yield_steps=2)
    assert speeds(guard, 2) == [0.0, 0.0]
    guard.filter(u, facing_wall, {"image_pose": away})  # passes: the run starts again
    assert speeds(guard, 3) == [0.0, 0.0, 0.0]
    guard.reset()
    assert speeds(guard, 3) == [0.0, 0.0, 0.0]
    for bad in (0, -1):
        with pytest.raises(ValueError, match="patience"):
            ImageGuard(city, patience=bad)
        with pytest.raises(ValueError, match="yield_steps"):
            ImageGuard(city, yield_steps=bad)


def test_with_agree_it_yields_only_to_a_belief_that_agrees_with_the_image(city, facing_wall):
    """``agree=0.3``: a belief 1.3 m off the image (a push) stays guarded however long; one
    0.1 m off gets the yield after ``patience`` vetoes."""
    info, u = {"image_pose": facing_wall}, np.array([0.9, 0.0])
    guard = ImageGuard(city, patience=2, yield_steps=1, agree=0.3)
    pushed = facing_wall + [0.0, 1.3, 0.0]
    assert [float(guard.filter(u, pushed, info)[0]) for _ in range(20)] == [0.0] * 20
    near = facing_wall + [0.1, 0.0, 0.0]
    assert [float(guard.filter(u, near, info)[0]) for _ in range(4)] == [0.0, 0.9, 0.0, 0.0]
    for bad in (0.0, -0.3, float("nan")):
        with pytest.raises(ValueError, match="agree"):
            ImageGuard(city, agree=bad)


def test_scripted_agent_passes_its_patience_to_the_guard(city, facing_wall):
    goal = facing_wall[:2] + [-6.0, 0.0]
    belief = {"pose_mean": facing_wall + [0.0, 0.0, np.pi], "pose_cov": np.ones(6) * 0.01,
              "goal": goal}
    info = {"belief_status": "tracking", "image_pose": facing_wall}
    agent = ScriptedAgent(city, guard=True, guard_patience=2)
    assert agent.guard.patience == 2 and ScriptedAgent(city, guard=True).guard.patience is None
    assert ScriptedAgent(city, guard=True, guard_agree=0.3).guard.agree == 0.3
    assert [agent.act(belief, info)[0] > 0 for _ in range(3)] == [False, False, True]
    agent.reset()  # a new episode forgets the yield
    assert agent.act(belief, info)[0] == 0.0


def test_memory_vetoes_from_a_recent_image_pose_carried_forward(city, facing_wall):
    """``memory=3``: an image pose at the wall, then images that alias 1.3 m away: the
    remembered pose (carried forward by the commands sent: turning on the spot keeps it in
    place) still vetoes for three steps, then it is forgotten; without memory the first
    aliased image lets the robot drive. A contact forgets them once its step is sent."""
    u, stop = np.array([0.9, 0.0]), np.array([0.0, 0.0])
    aliased = {"image_pose": facing_wall + [0.0, 1.3, np.pi]}  # faces away from the wall

    def run(guard: ImageGuard, later: list[dict]) -> list[float]:
        assert guard.blocks(u, facing_wall, {"image_pose": facing_wall})
        guard.remember(stop, {"image_pose": facing_wall})
        out = []
        for info in later:
            v = float(guard.filter(u, facing_wall, info)[0])
            guard.remember(np.array([v, 0.0]), info)
            out.append(v)
        return out

    assert run(ImageGuard(city), [aliased] * 5) == [0.9] * 5
    assert run(ImageGuard(city, memory=3), [aliased] * 5) == [0.0, 0.0, 0.0, 0.9, 0.9]
    nan = {"image_pose": np.full(3, np.nan)}  # images without a pose keep their slot
    assert run(ImageGuard(city, memory=3), [nan] * 4) == [0.0, 0.0, 0.0, 0.9]
    bumped = {**aliased, "collision": True}
    assert run(ImageGuard(city, memory=3), [bumped, aliased]) == [0.0, 0.9]  # then forgets
    guard = ImageGuard(city, memory=3)
    run(guard, [])
    guard.reset()
    assert not guard.blocks(u, facing_wall, aliased)


def test_memory_carries_poses_by_the_motion_model(city, facing_wall):
    """A pose remembered while the robot backed off 0.3 m/s for 4 steps of 0.1 s lies
    0.12 m farther from the wall, as F says."""
    guard = ImageGuard(city, memory=5, dt=0.1)
    info = {"image_pose": facing_wall}
    guard.remember(np.array([-0.3, 0.0]), info)
    for _ in range(3):
        guard.remember(np.array([-0.3, 0.0]), {"image_pose": None})
    np.testing.assert_allclose(guard._poses[0], facing_wall - [0.12, 0.0, 0.0], atol=1e-12)
    assert [p is None for p in guard._poses] == [False, True, True, True]


def test_scripted_agent_remembers_every_command_it_sends(city, facing_wall):
    """The agent hands every command to the guard's memory, a back-off too, and passes
    ``guard_memory`` on; memory 0 remembers nothing."""
    belief = {"pose_mean": facing_wall + [0.0, 0.0, np.pi], "pose_cov": np.ones(6) * 0.01,
              "goal": facing_wall[:2] + [-6.0, 0.0]}
    agent = ScriptedAgent(city, guard=True, guard_memory=2)
    assert agent.guard.memory == 2 and ScriptedAgent(city, guard=True).guard.memory == 0
    agent.act(belief, {"belief_status": "tracking", "image_pose": facing_wall})
    assert len(agent.guard._poses) == 1
    u = agent.act(belief, {"belief_status": "tracking", "image_pose": facing_wall,
                           "collision": True})  # a contact: the agent backs off
    assert u[0] < 0 and agent.guard._poses == []
    for bad in (-1, 1.5):
        with pytest.raises((TypeError, ValueError), match="memory"):
            ImageGuard(city, memory=bad)
    with pytest.raises(ValueError, match="dt"):
        ImageGuard(city, dt=0.0)


def test_bad_settings(city):
    with pytest.raises(TypeError, match="guard must be True or False"):
        ScriptedAgent(city, guard="yes")
    with pytest.raises(ValueError, match="horizon"):
        ImageGuard(city, horizon=0.0)
    with pytest.raises(ValueError, match="radius"):
        ImageGuard(city, radius=-1.0)
