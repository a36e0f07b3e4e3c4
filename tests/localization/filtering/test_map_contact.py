"""A contact where the map has room contradicts the belief: "lost" for a while."""

from __future__ import annotations

import numpy as np
import pytest

from localization.filtering.map_contact import (
    CONTACT_CLEARANCE,
    CONTACT_LOST_STEPS,
    CONTACT_SLACK,
    PUSH_SPEED,
    PUSH_TURN_RATE,
    REPEAT_CONTACT_STEPS,
    ROBOT_RADIUS,
    blocked_motion,
    check_bearing,
    check_free_space,
    contact_contradicts,
    contact_kinds,
    contact_points,
    contact_projection,
    touched_points,
)

X = np.array([1.0, 2.0, 0.3])


class Map:
    """A free_space that answers ``free`` and records the margins it was asked about."""

    def __init__(self, free: bool) -> None:
        self.free, self.margins = free, []

    def __call__(self, points: np.ndarray, margin: float) -> np.ndarray:
        assert points.ndim == 2 and points.shape[1] == 2
        self.margins.append(margin)
        return np.full(len(points), self.free)


def test_a_contact_contradicts_only_where_the_map_has_room() -> None:
    room, wall = Map(True), Map(False)
    assert contact_contradicts(room, X, np.diag([0.0, 0.0, 0.1]))
    assert not contact_contradicts(wall, X, np.diag([0.0, 0.0, 0.1]))
    assert room.margins == [pytest.approx(CONTACT_CLEARANCE)]


def test_the_room_needed_grows_with_the_position_uncertainty() -> None:
    """Two standard deviations along the widest axis: a wide belief may be at a wall."""
    room = Map(True)
    contact_contradicts(room, X, np.array([[0.09, 0.0, 0.0], [0.0, 0.01, 0.0],
                                           [0.0, 0.0, 1.0]]))
    assert room.margins == [pytest.approx(CONTACT_CLEARANCE + 0.6)]


class HalfPlane:
    """A free_space with a wall: everything at ``(p - origin) . normal > 0`` is a building."""

    def __init__(self, origin: np.ndarray, normal: np.ndarray) -> None:
        self.origin, self.normal = np.asarray(origin, float), np.asarray(normal, float)

    def __call__(self, points: np.ndarray, margin: float) -> np.ndarray:
        return (points - self.origin) @ self.normal < -margin


def _wall(x: np.ndarray, angle: float, distance: float) -> HalfPlane:
    """A wall ``distance`` m from the pose ``x`` in the direction ``x[2] + angle``."""
    u = np.array([np.cos(x[2] + angle), np.sin(x[2] + angle)])
    return HalfPlane(x[:2] + distance * u, u)


P_SMALL = np.diag([0.05 ** 2, 0.05 ** 2, 0.05 ** 2])


@pytest.mark.parametrize("bearing", [0.0, np.pi / 2, -2.5])
def test_a_bearing_asks_the_map_only_at_the_side_that_was_touched(bearing: float) -> None:
    """A wall at the robot's rim where it was touched explains the contact; the same wall
    on the other side does not (without a bearing it does: the rule around the mean)."""
    at_contact = _wall(X, bearing, ROBOT_RADIUS)
    opposite = _wall(X, bearing + np.pi, ROBOT_RADIUS)
    assert not contact_contradicts(at_contact, X, P_SMALL, bearing)
    assert contact_contradicts(opposite, X, P_SMALL, bearing)
    assert not contact_contradicts(opposite, X, P_SMALL)
    assert not contact_contradicts(opposite, X, P_SMALL, np.nan)  # NaN: no bearing


def test_a_wide_belief_may_be_touched_at_a_wall_two_sigma_away() -> None:
    """A wall 0.5 m beyond the touched rim: explained for a belief 0.3 m wide (2 sigma
    reaches it), a contradiction for one 0.05 m wide; a heading too uncertain to tell a
    side (2 sigma >= pi) falls back to the rule around the mean."""
    wall = _wall(X, 0.0, ROBOT_RADIUS + 0.5)
    assert contact_contradicts(wall, X, P_SMALL, 0.0)
    assert not contact_contradicts(wall, X, np.diag([0.3 ** 2, 0.3 ** 2, 0.05 ** 2]), 0.0)
    behind = _wall(X, np.pi, 0.3)
    assert contact_contradicts(behind, X, np.diag([0.05 ** 2, 0.05 ** 2, 0.8 ** 2]), 0.0)
    assert not contact_contradicts(behind, X, np.diag([0.05 ** 2, 0.05 ** 2, 1.6 ** 2]), 0.0)


def test_contact_points_cover_the_two_sigma_ellipsoid() -> None:
    """Every pose inside the 2-sigma ellipsoid is touched within ``spacing`` of a grid
    point, and no grid point lies outside it."""
    P = np.array([[0.09, 0.03, 0.01], [0.03, 0.04, 0.0], [0.01, 0.0, 0.2]])
    points, spacing = contact_points(X, P, 0.7)
    rng = np.random.default_rng(0)
    s = rng.normal(size=(2000, 3))
    s *= rng.uniform(0, 1, (2000, 1)) ** (1 / 3) / np.linalg.norm(s, axis=1, keepdims=True)
    poses = X + 2.0 * s @ np.linalg.cholesky(P).T
    touched = poses[:, :2] + ROBOT_RADIUS * np.stack([np.cos(poses[:, 2] + 0.7),
                                                      np.sin(poses[:, 2] + 0.7)], -1)
    gaps = np.linalg.norm(touched[:, None] - points[None], axis=2).min(axis=1)
    assert gaps.max() <= spacing
    assert np.linalg.norm(points - X[:2], axis=1).max() <= 2 * 0.3 + ROBOT_RADIUS + 1e-9
    assert 0.0 < CONTACT_SLACK < CONTACT_CLEARANCE - ROBOT_RADIUS


def test_the_contact_likelihood_of_particles_asks_the_map_at_their_touched_point() -> None:
    """0 where a wall is at the touched rim, log CONTACT_MISS where the map has room; without
    a bearing, a wall anywhere within CONTACT_CLEARANCE explains it."""
    from localization.filtering.map_contact import CONTACT_MISS, contact_log_likelihood

    wall = HalfPlane(np.array([1.0, 0.0]), np.array([1.0, 0.0]))  # buildings at x > 1
    X = np.array([[1.0 - ROBOT_RADIUS, 0.0, 0.0], [1.0 - ROBOT_RADIUS, 0.0, np.pi],
                  [-3.0, 0.0, 0.0]])
    np.testing.assert_allclose(contact_log_likelihood(wall, X, 0.0),
                               [0.0, np.log(CONTACT_MISS), np.log(CONTACT_MISS)])
    np.testing.assert_allclose(contact_log_likelihood(wall, X),
                               [0.0, 0.0, np.log(CONTACT_MISS)])
    np.testing.assert_allclose(contact_log_likelihood(wall, X, np.nan),
                               contact_log_likelihood(wall, X))


def test_the_touched_point_is_on_the_robots_rim_at_the_bearing() -> None:
    np.testing.assert_allclose(touched_points(X[None], 0.0)[0],
                               X[:2] + ROBOT_RADIUS * np.array([np.cos(0.3), np.sin(0.3)]))
    np.testing.assert_allclose(touched_points(X[None], np.pi / 2)[0],
                               X[:2] + ROBOT_RADIUS * np.array([-np.sin(0.3), np.cos(0.3)]))


def test_bad_bearings_are_named() -> None:
    assert check_bearing(None) is None and check_bearing(float("nan")) is None
    assert check_bearing(np.float32(1.5)) == pytest.approx(1.5)
    with pytest.raises(TypeError, match="bearing must be None or a float"):
        check_bearing("ahead")
    with pytest.raises(TypeError, match="bearing must be None or a float"):
        check_bearing(True)


def test_bad_maps_are_named() -> None:
    with pytest.raises(TypeError, match="free_space must be None or a callable"):
        check_free_space(np.ones(3))
    assert check_free_space(None) is None
    with pytest.raises(ValueError, match="one bool per point"):
        contact_contradicts(lambda p, m: np.ones((2, 2), bool), X, np.eye(3))


def _tracking(localizer, drive, free_space, steps: int = 60, **options):
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    images, poses, controls = drive
    W = localizer.transform(images)
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model, free_space=free_space, **options)
    env.close()
    f.reset(W[0], poses[0], np.diag([0.01, 0.01, 0.001]))
    for t in range(1, steps):
        f.step(controls[t - 1], W[t])
    assert f.belief_status == "tracking"
    return f, W, controls


def test_a_contradicting_contact_makes_the_belief_lost_for_a_while(localizer, drive):
    """Tracking, a bump where the map has room: "lost" (the agent stops and looks) for
    CONTACT_LOST_STEPS steps though the images are accepted, then tracking again."""
    f, W, controls = _tracking(localizer, drive, Map(True))
    f.step(controls[59], W[60], contact=True)
    statuses = [f.belief_status]
    for t in range(61, 61 + CONTACT_LOST_STEPS):
        f.step(controls[t - 1], W[t])
        statuses.append(f.belief_status)
    assert statuses == ["lost"] * CONTACT_LOST_STEPS + ["tracking"], statuses


def test_a_contact_makes_a_restart_on_trial_lost_too(localizer, drive):
    """A belief started from the first image is "relocalizing" until the images confirm it;
    a contradicting contact makes it "lost" (the agent stops) for CONTACT_LOST_STEPS steps,
    as a tracking belief, then "relocalizing" again while its trial is still open (here:
    views off the maps). Before, a restart on trial could not be lost: on tuning city 13 one
    whose images fell off the maps drove into a kiosk 30 times."""
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    images, _, controls = drive
    W = localizer.transform(images)
    off_maps = W[0] + 50.0 * W.std(axis=0)  # psi* and every measurement NaN
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model, free_space=Map(True))
    env.close()
    f.reset(W[0])
    assert f.belief_status == "relocalizing" and f._trial is not None
    steps = [f.step(controls[0], off_maps, contact=("city",))[1]]
    beliefs = [f.belief_status]
    for t in range(1, CONTACT_LOST_STEPS + 1):
        steps.append(f.step(controls[t], off_maps)[1])
        beliefs.append(f.belief_status)
    assert set(steps) == {"out_of_domain"} and f._trial is not None
    assert beliefs == ["lost"] * CONTACT_LOST_STEPS + ["relocalizing"], " ".join(beliefs)


@pytest.mark.parametrize("free_space", [Map(False), None], ids=["at a wall", "no map"])
def test_a_second_bump_soon_after_makes_a_coasting_belief_lost(localizer, drive, free_space):
    """Every contact explained by the map (or no map): a tracking belief bumped twice stays
    "tracking"; a "doubtful" one (coasting through views off the maps) is "lost" at its
    second contact within REPEAT_CONTACT_STEPS, not at the first, nor at one that goes on."""
    f, W, controls = _tracking(localizer, drive, free_space)
    for t in (60, 62):
        f.step(controls[t - 1], W[t], contact=("city",))
        f.step(controls[t], W[t + 1])
    assert f.belief_status == "tracking"
    off_maps = W[0] + 50.0 * W.std(axis=0)
    beliefs = []
    for t, touch in enumerate([False] * 30 + [True, True, False, True]):
        f.step(controls[64 + t], off_maps, contact=("city",) if touch else False)
        beliefs.append(f.belief_status)
    assert beliefs[29:] == ["doubtful"] * 4 + ["lost"], beliefs
    f, W, controls = _tracking(localizer, drive, free_space)
    for t in range(64, 94):
        f.step(controls[t], off_maps)
    f.step(controls[94], off_maps, contact=("city",))
    for t in range(95, 96 + REPEAT_CONTACT_STEPS):
        f.step(controls[t], off_maps)
    f.step(controls[96 + REPEAT_CONTACT_STEPS], off_maps, contact=("city",))
    assert f.belief_status == "doubtful"  # the second contact came too late


def test_a_new_episode_forgets_the_last_ones_contacts(localizer, drive):
    """reset() starts the contact history afresh: a bump at the end of one episode and one
    early in the next are not "a second bump" (without the reset, they are)."""
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    images, _, controls = drive
    W = localizer.transform(images)
    env = make_env()
    statuses = []
    for new_episode in (True, False):
        f = BeliefFilter(localizer, env.unwrapped.motion_model, free_space=Map(False))
        f.reset(W[0])
        f.step(controls[0], W[1], contact=("city",))
        if new_episode:
            f.reset(W[0])
        f.step(controls[1], W[2])
        f.step(controls[2], W[3], contact=("city",))
        statuses.append(f.belief_status)
    env.close()
    assert statuses[0] != "lost" and statuses[1] == "lost", statuses


class Behind:
    """A wall 0.3 m behind wherever the belief ``f`` is (0.1 m from the robot's rim)."""

    def __init__(self) -> None:
        self.f = None

    def __call__(self, points: np.ndarray, margin: float) -> np.ndarray:
        return _wall(self.f.x, np.pi, 0.3)(points, margin)


@pytest.mark.parametrize(("bearing", "status"), [(0.0, "lost"), (np.pi, "tracking"),
                                                 (None, "tracking")])
def test_the_filter_asks_the_map_where_the_bumper_was_touched(localizer, drive, bearing,
                                                               status):
    """A wall just behind the belief explains a contact behind it, or one of unknown side,
    but not one ahead: that belief is wrong ("lost")."""
    behind = Behind()
    f, W, controls = _tracking(localizer, drive, behind)
    behind.f = f
    f.step(controls[59], W[60], contact=("city",), bearing=bearing)
    assert f.belief_status == status


@pytest.mark.parametrize("free_space", [Map(False), None], ids=["at a wall", "no map"])
def test_a_contact_the_map_explains_or_without_a_map_changes_nothing(localizer, drive,
                                                                      free_space):
    """With the commanded motion; the blocked one is below."""
    f, W, controls = _tracking(localizer, drive, free_space, contact_motion="commanded")
    x = f.x
    f.step(controls[59], W[60], contact=True)
    g, _, _ = _tracking(localizer, drive, free_space, steps=61, contact_motion="commanded")
    assert f.belief_status == "tracking" and np.array_equal(f.x, g.x) and not np.array_equal(x, f.x)
    assert np.array_equal(f.P, g.P)


def test_blocked_motion_keeps_the_turn_and_makes_the_step_its_uncertainty() -> None:
    from envs.motion_model import UnicycleModel

    model = UnicycleModel(0.1)
    u_blocked, Q = blocked_motion(model, X, np.array([0.8, 0.5]))
    np.testing.assert_array_equal(u_blocked, [0.0, 0.5])
    d = np.hypot(*(model.predict(X, [0.8, 0.5])[:2] - X[:2]))  # the turn does not translate
    np.testing.assert_allclose(Q, np.diag([d * d, d * d, 0.05 ** 2]))
    assert d == pytest.approx(0.08, rel=0.01)


def test_a_push_by_a_mover_widens_the_step_by_the_mover_s_step() -> None:
    from envs.motion_model import UnicycleModel

    model = UnicycleModel(0.1)
    u, Q = blocked_motion(model, X, np.array([0.8, 0.5]))
    u_pushed, Q_pushed = blocked_motion(model, X, np.array([0.8, 0.5]), pushed=True)
    np.testing.assert_array_equal(u_pushed, u)
    np.testing.assert_allclose(Q_pushed - Q, np.diag([(PUSH_SPEED * 0.1) ** 2] * 2
                                                     + [(PUSH_TURN_RATE * 0.1) ** 2]))


def test_the_push_constants_are_the_env_s_movers_and_robot() -> None:
    """The filter does not import the env; its push model must stay in step with it."""
    from envs.robot import ROBOT_RADIUS as ENV_ROBOT_RADIUS
    from envs.traffic import PEDESTRIAN_SPEED, VEHICLE_SPEED

    assert PUSH_SPEED == max(*VEHICLE_SPEED, *PEDESTRIAN_SPEED)
    assert PUSH_TURN_RATE == pytest.approx(PUSH_SPEED / ROBOT_RADIUS)
    assert ROBOT_RADIUS == ENV_ROBOT_RADIUS


def test_contact_kinds_read_the_env_s_collision_with() -> None:
    assert contact_kinds(True) == {"city"} and contact_kinds(np.bool_(False)) == frozenset()
    assert contact_kinds(("city", "traffic")) == {"city", "traffic"}
    assert contact_kinds(()) == frozenset()
    with pytest.raises(ValueError, match="contact: unknown contact kinds \\['wall'\\]"):
        contact_kinds(("wall",))
    with pytest.raises(TypeError, match="contact must be a bool or a collection"):
        contact_kinds("traffic")


def test_a_contact_with_traffic_does_not_contradict_the_map(localizer, drive):
    """Movers are not on the map: a bump into one where the map has room leaves the belief
    tracking (a bump into the city there makes it "lost", above), with the mover's push
    in P."""
    f, W, controls = _tracking(localizer, drive, Map(True))
    g, _, _ = _tracking(localizer, drive, Map(True))
    f.step(controls[59], W[60], contact=("traffic",))
    g.step(controls[59], W[60], contact=True)
    assert f.belief_status == "tracking" and g.belief_status == "lost"
    assert f.ekf.P_prior[2, 2] > g.ekf.P_prior[2, 2] + 0.5 * (PUSH_TURN_RATE * 0.1) ** 2
    with pytest.raises(ValueError, match="unknown contact kinds"):
        f.step(controls[60], W[61], contact=("bus",))


def test_a_blocked_contact_step_predicts_no_translation(localizer, drive):
    """The default: a contact step is predicted as blocked, whatever the map says."""
    import copy

    f, W, controls = _tracking(localizer, drive, Map(False))
    g = copy.deepcopy(f)
    f.step(controls[59], W[60], contact=True)
    g.ekf.predict(*blocked_motion(g.motion_model, g.x, g.gain * controls[59]))
    np.testing.assert_allclose(f.ekf.x_prior, g.ekf.x_prior)
    np.testing.assert_allclose(f.ekf.P_prior, g.ekf.P_prior)
    assert np.hypot(*(f.ekf.x_prior[:2] - g.x[:2])) < 1e-9
    with pytest.raises(ValueError, match="contact_motion"):
        _tracking(localizer, drive, None, steps=2, contact_motion="slide")


def test_the_wrapper_feels_contacts_against_the_city_by_default(localizer) -> None:
    from localization.wrappers import BeliefWrapper
    from tests.localization.conftest import make_env

    env = make_env()
    assert BeliefWrapper(env, localizer).belief.free_space == env.unwrapped.city.free_mask
    off = BeliefWrapper(env, localizer, filter_options={"free_space": None})
    assert off.belief.free_space is None
    env.close()


def test_the_wrapper_passes_the_bumper_to_the_belief(localizer) -> None:
    """Driving straight on until the robot touches something: with a map that has room
    everywhere, the contact makes the belief "lost" on that very step."""
    from localization.wrappers import BeliefWrapper
    from tests.localization.conftest import make_env

    env = BeliefWrapper(make_env(), localizer, filter_options={"free_space": Map(True)})
    env.reset(seed=0)
    for _ in range(400):
        _, _, terminated, truncated, info = env.step(np.array([0.9, 0.0]))
        if info["collision"] or terminated or truncated:
            break
    env.close()
    assert info["collision"] and info["collision_with"] == ("city",)
    assert abs(info["collision_bearing"]) < 1.0  # driving straight on: touched ahead
    assert info["belief_status"] == "lost"


def test_the_wrapper_reads_what_was_touched_or_falls_back_to_the_bumper() -> None:
    from localization.wrappers import _contact

    assert _contact({"collision": True, "collision_with": ("traffic",)}) == ("traffic",)
    assert _contact({"collision": False, "collision_with": ()}) == ()
    assert _contact({"collision": True}) is True  # an env that does not say what
    assert _contact({}) is False


@pytest.mark.parametrize("bearing", [0.0, 0.7, -np.pi / 2, 2.8])
def test_the_projection_moves_the_belief_to_the_wall_it_was_touched_at(bearing: float) -> None:
    """A wall 1 m from the belief in the touched direction: the nearest pose that explains
    the contact has its touched point within CONTACT_SLACK of the wall, its centre free,
    the heading kept, and lies towards the wall (about 1 - ROBOT_RADIUS m away)."""
    wall = _wall(X, bearing, 1.0)
    pose = contact_projection(wall, X, P_SMALL, bearing)
    assert pose is not None and pose[2] == X[2]
    assert not wall(touched_points(pose[None], bearing), CONTACT_SLACK)[0]
    assert wall(pose[None, :2], ROBOT_RADIUS - CONTACT_SLACK)[0]
    shift = pose[:2] - X[:2]
    towards = np.array([np.cos(X[2] + bearing), np.sin(X[2] + bearing)])
    assert shift @ towards == pytest.approx(1.0 - ROBOT_RADIUS, abs=0.1)
    assert np.hypot(*shift) == pytest.approx(1.0 - ROBOT_RADIUS, abs=0.1)  # straight at it


def test_the_projection_prefers_the_direction_the_belief_is_unsure_in() -> None:
    """Mahalanobis, not Euclidean: a wall 0.8 m ahead, touched ahead; a belief unsure along
    its heading and sure sideways moves straight along it (None when nothing explains the
    contact within the reach)."""
    ahead = HalfPlane(X[:2] + 0.8 * np.array([np.cos(X[2]), np.sin(X[2])]),
                      np.array([np.cos(X[2]), np.sin(X[2])]))
    body = np.array([[np.cos(X[2]), -np.sin(X[2])], [np.sin(X[2]), np.cos(X[2])]])
    P = np.eye(3) * 0.01
    P[:2, :2] = body @ np.diag([1.0, 0.01]) @ body.T  # sure sideways, unsure along
    pose = contact_projection(ahead, X, P, 0.0)
    along = (pose[:2] - X[:2]) @ body
    assert along[0] == pytest.approx(0.8 - ROBOT_RADIUS, abs=0.1) and abs(along[1]) < 0.06
    assert contact_projection(Map(True), X, P_SMALL, 0.0) is None


@pytest.mark.parametrize("project", [True, False])
def test_the_filter_projects_a_contradicted_belief_onto_the_touched_wall(localizer, drive,
                                                                        project: bool):
    """``project_contacts``: a bump ahead with the wall 1 m ahead of the belief moves the
    mean to the wall (and the belief is "lost" either way); off, the mean stays."""
    holder = {}
    f, W, controls = _tracking(localizer, drive, lambda p, m: holder["wall"](p, m),
                               project_contacts=project)
    x = f.x
    holder["wall"] = _wall(x, 0.0, 1.0)
    f.step(controls[59], W[60], contact=("city",), bearing=0.0)
    ahead = (f.x[:2] - x[:2]) @ np.array([np.cos(x[2]), np.sin(x[2])])
    assert f.belief_status == "lost"
    if project:
        assert ahead == pytest.approx(1.0 - ROBOT_RADIUS, abs=0.15)
    else:
        assert abs(ahead) < 0.15


def test_project_contacts_must_be_a_bool(localizer) -> None:
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    env = make_env()
    with pytest.raises(TypeError, match="project_contacts"):
        BeliefFilter(localizer, env.unwrapped.motion_model, project_contacts="yes")
    env.close()
