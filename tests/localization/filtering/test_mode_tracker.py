"""ModeTracker: the EKF on the particle belief's dominant hypothesis (``track_mode``).

Unit tests on the small city-0 localizer of ``tests/localization/conftest.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

import envs  # noqa: F401
from envs.motion_model import UnicycleModel
from localization.filtering.particles import ParticleBelief

DT = 0.1


def _belief(localizer, **kw) -> ParticleBelief:
    return ParticleBelief(localizer, UnicycleModel(DT),
                          **{"n_particles": 500, "seed": 0, "track_mode": True, **kw})


def _cloud(centre, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.asarray(centre) + rng.normal(0.0, [0.1, 0.1, 0.02], (n, 3))


def test_reports_the_ekf_while_the_particles_support_it(localizer, features):
    W, poses, controls = features
    pf = _belief(localizer)
    pf.reset(W[0], x0=poses[0])
    for k in range(5):
        pf.step(controls[k], W[k + 1])
    assert pf.tracker.source == "ekf" and pf.tracker.support >= pf.tracker.support_weight
    np.testing.assert_array_equal(pf.pose_mean, pf.tracker.ekf.x)
    np.testing.assert_array_equal(pf.pose_cov, pf.tracker.ekf.P)


def test_a_strongly_contradicted_ekf_restarts_where_the_particles_are(localizer, features):
    """The EKF (not the particles) thrown 6 m off, as a kidnap does to it: its NIS exceeds
    ``strong_nis`` and after ``strong_steps`` such steps it restarts at the particles."""
    W, poses, controls = features
    pf = _belief(localizer, max_injection=0.0, track_mode={"strong_steps": 3})
    pf.reset(W[0], x0=poses[0])
    pf.tracker.ekf.ekf.x = poses[0] + np.array([6.0, 0.0, 0.0])
    sources, statuses = [], []
    for k in range(pf.tracker.strong_steps):
        pf.step(controls[k], W[k + 1])
        sources.append(pf.tracker.source)
        statuses.append(pf.status)
    assert sources[:-1] == ["ekf"] * (pf.tracker.strong_steps - 1), sources
    assert sources[-1] == "restarted" and pf.tracker.restarts == 1
    assert "tracking" not in statuses[:-1], statuses  # while it disagreed, the status said so
    k = pf.tracker.strong_steps
    assert np.hypot(*(pf.pose_mean[:2] - poses[k, :2])) < 0.5


def test_an_ekf_the_particles_left_restarts_after_max_unsupported_steps(localizer, features):
    """The particles (not the EKF) moved 6 m: the EKF's own images still agree with it, so
    it holds (status "doubtful") for ``max_unsupported`` steps, then restarts there. (With
    ``unconfirm_steps`` the images soon withdraw the particles' confirmation and the steady
    injection brings particles back to the EKF: the next test; here it is off.)"""
    W, poses, _controls = features
    pf = _belief(localizer, max_injection=0.0, unconfirm_steps=None)
    pf.reset(W[0], x0=poses[0])
    far = poses[0] + np.array([6.0, 0.0, 0.0])
    pf._set(_cloud(far, pf.n_particles))
    for k in range(pf.tracker.max_unsupported - 1):
        pf.step(np.zeros(2), W[0])
        assert pf.tracker.source == "ekf" and pf.status != "tracking", (k, pf.status)
        assert np.hypot(*(pf.pose_mean[:2] - poses[0, :2])) < 0.5
    pf.step(np.zeros(2), W[0])
    assert pf.tracker.source == "restarted" and pf.tracker.restarts == 1
    assert np.hypot(*(pf.pose_mean[:2] - far[:2])) < 0.5


def test_images_that_withdraw_the_confirmation_bring_the_particles_back(localizer, features):
    """The same move with the defaults: the images stop agreeing with the particles' mode,
    which is unconfirmed after ``unconfirm_steps`` frames; the steady injection then seeds
    particles where the images point (the EKF's pose), so the EKF keeps its support and is
    never restarted at the particles' wrong place."""
    W, poses, _controls = features
    pf = _belief(localizer, max_injection=0.0)
    pf.reset(W[0], x0=poses[0])
    far = poses[0] + np.array([6.0, 0.0, 0.0])
    pf._set(_cloud(far, pf.n_particles))
    for _ in range(pf.tracker.max_unsupported + 5):
        pf.step(np.zeros(2), W[0])
    assert pf.tracker.source == "ekf" and pf.tracker.restarts == 0
    assert np.hypot(*(pf.pose_mean[:2] - poses[0, :2])) < 0.5
    # the heaviest mode came back to the images' side (measured 1.3 m from the EKF's pose)
    mode = pf.modes[0].mean[:2]
    assert np.hypot(*(mode - poses[0, :2])) < np.hypot(*(mode - far[:2])) / 2


def test_a_condemned_ekf_and_two_distant_modes_report_the_heavier_mode(localizer, features):
    W, poses, _controls = features
    pf = _belief(localizer, max_injection=0.0)
    pf.reset(W[0], x0=poses[0])
    a, b = poses[0] + np.array([6.0, 0.0, 0.0]), poses[0] + np.array([0.0, 6.0, 0.0])
    n = pf.n_particles
    pf._set(np.vstack([_cloud(a, n // 2, 1), _cloud(b, n - n // 2, 2)]),
            np.log(np.where(np.arange(n) < n // 2, 1.2, 1.0)))
    pf.tracker.condemned = True
    ekf_before = pf.tracker.ekf.x
    pf.tracker.step(np.zeros(2), W[0], pf.particles, pf.weights, pf.modes[0])
    assert pf.tracker.source == "mode" and pf.tracker.restarts == 0  # 55 %: not confident
    np.testing.assert_allclose(pf.pose_mean, pf.modes[0].mean)
    assert np.hypot(*(pf.pose_mean[:2] - a[:2])) < 0.5  # the heavier of the two
    assert np.hypot(*(pf.tracker.ekf.x[:2] - ekf_before[:2])) < 0.5  # the EKF was kept


def test_an_unknown_start_reports_the_particles_until_they_agree(localizer, features):
    W, _poses, _controls = features
    pf = _belief(localizer)
    pf.reset(W[0])  # from the image's proposals
    assert pf.tracker.condemned
    np.testing.assert_array_equal(pf.pose_mean, pf.modes[0].mean)


def test_same_seed_same_run(localizer, features):
    W, poses, controls = features
    a = _belief(localizer, seed=5).run(W[:40], controls[:39], x0=poses[0])
    b = _belief(localizer, seed=5).run(W[:40], controls[:39], x0=poses[0])
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


@pytest.mark.parametrize("track_mode, error, match", [
    ("yes", TypeError, "track_mode"),
    ({"support_weight": 0.0}, ValueError, "support_weight"),
    ({"radius": -1.0}, ValueError, "radius"),
    ({"strong_steps": 0}, ValueError, "strong_steps"),
    ({"probation": 1.5}, TypeError, "probation"),
    ({"surport_weight": 0.1}, TypeError, "surport_weight"),
])
def test_bad_settings_raise_clear_errors(localizer, track_mode, error, match):
    with pytest.raises(error, match=match):
        _belief(localizer, track_mode=track_mode)


def test_the_tracker_ekf_has_the_drift_test_alone(localizer):
    """``drift=True``: the tracker's EKF runs the divergence monitor's drift test only (no
    restart or "lost" of its own: the particles decide those); by default, as the EKF's, it
    runs none; anything else than a bool is named."""
    from localization.filtering.divergence import DRIFT_DISTANCE
    from localization.filtering.mode_tracker import ModeTracker

    model = UnicycleModel(DT)
    monitor = ModeTracker(localizer, model, drift=True).ekf.monitor
    assert monitor.drift_only and monitor.drift_distance == DRIFT_DISTANCE
    assert ModeTracker(localizer, model).ekf.monitor is None
    assert ModeTracker(localizer, model, drift=False).ekf.monitor is None
    with pytest.raises(TypeError, match="drift"):
        ModeTracker(localizer, model, drift="yes")


def test_the_tracker_ekf_has_the_offset_test_on_request(localizer):
    """``offset_doubt``: the tracker's EKF runs the monitor's offset test (status only), with
    or without the drift test; no doubt before any image."""
    from localization.filtering.divergence import DRIFT_DISTANCE
    from localization.filtering.mode_tracker import ModeTracker

    model = UnicycleModel(DT)
    monitor = ModeTracker(localizer, model, offset_doubt=0.5).ekf.monitor
    assert monitor.drift_only and monitor.offset_doubt == 0.5 and monitor.drift_distance is None
    both = ModeTracker(localizer, model, drift=True, offset_doubt=0.3).ekf.monitor
    assert both.drift_distance == DRIFT_DISTANCE and both.offset_doubt == 0.3
    assert not ModeTracker(localizer, model, offset_doubt=0.5).images_doubt
    with pytest.raises(ValueError, match="offset_doubt"):
        ModeTracker(localizer, model, offset_doubt=-1.0)


def test_a_report_whose_images_the_tracker_doubts_is_doubtful(localizer, features,
                                                               monkeypatch):
    """A right start tracks; once the tracker's monitor doubts the images (its offset test,
    stubbed here: the scenario is the robustness benchmark's push rows), the belief says
    "doubtful" instead of "tracking"."""
    from localization.filtering.mode_tracker import ModeTracker

    W, poses, controls = features
    seen = {}
    for doubt in (False, True):
        monkeypatch.setattr(ModeTracker, "images_doubt", property(lambda self, d=doubt: d))
        pf = _belief(localizer)
        pf.reset(W[0], x0=poses[0])
        for k in range(5):
            pf.step(controls[k], W[k + 1])
        seen[doubt] = pf.belief_status
    assert seen == {False: "tracking", True: "doubtful"}


@pytest.mark.parametrize("tracker_map", [True, False], ids=["tracker with the map", "without"])
def test_a_contact_the_tracker_ekf_cannot_explain_moves_it_to_the_wall(localizer, features,
                                                                     tracker_map: bool):
    """A wall 1 m ahead of the reported EKF, touched ahead, the particles already at it (so
    they are not contradicted and their contact spread does not run): the tracker's EKF,
    with the particles' map, projects itself onto the wall; given no map it stays put
    (what a pushed robot's report did before, bumping the same wall again and again)."""
    from localization.filtering.map_contact import ROBOT_RADIUS
    from tests.localization.filtering.test_map_contact import _wall

    W, poses, _controls = features
    x = poses[0]
    wall = _wall(x, 0.0, 1.0)
    pf = _belief(localizer, max_injection=0.0, free_space=wall,
                 track_mode={} if tracker_map else {"free_space": None})
    pf.reset(W[0], x0=x)
    ahead = np.array([np.cos(x[2]), np.sin(x[2])])
    pf._set(_cloud(x + np.r_[(1.0 - ROBOT_RADIUS) * ahead, 0.0], pf.n_particles))
    pf.step(np.zeros(2), W[0], contact=("city",), bearing=0.0)
    assert pf.status != "lost"  # the particles explain the contact
    moved = (pf.pose_mean[:2] - x[:2]) @ ahead
    if tracker_map:
        assert moved == pytest.approx(1.0 - ROBOT_RADIUS, abs=0.15)
    else:
        assert abs(moved) < 0.15
