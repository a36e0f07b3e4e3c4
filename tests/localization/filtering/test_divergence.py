"""DivergenceMonitor's graded evidence: one bad image is doubt, an aliased run is not a
restart, a strong or sustained contradiction restarts where the images agree."""

from __future__ import annotations

import numpy as np
import pytest

from localization.filtering.divergence import DRIFT_CHANGE, DRIFT_DISTANCE, DivergenceMonitor

X = np.zeros(3)
P = np.diag([0.01, 0.01, 0.001])
FAR = np.array([6.0, 0.0, 0.0])  # psi* 6 m from the belief: disagrees
NEAR = np.array([0.05, 0.0, 0.0])


class Still:
    """A motion model for a robot at rest: F(X, U) = X."""

    def predict_many(self, X, u):
        return X


def feed(monitor, steps, nis, psi, rejected, u=(0.5, 0.0)):
    """``steps`` steps as BeliefFilter runs them: the stored proposals move (and age; the
    ``Still`` model leaves them where they are whatever the control ``u``), then the step is
    observed."""
    verdicts = []
    for _ in range(steps):
        monitor.move_proposals(Still(), np.asarray(u, dtype=np.float64))
        verdicts.append(monitor.observe(nis, 3, psi, X, P, rejected))
    return verdicts


def test_one_bad_image_is_doubt_not_lost():
    m = DivergenceMonitor()
    feed(m, 8, 1.5, NEAR, False)
    v, = feed(m, 1, 5000.0, NEAR, True)
    assert v.doubtful and not v.lost and v.restart is None
    assert not feed(m, 1, 1.5, NEAR, False)[0].lost


def test_an_aliased_run_says_lost_but_does_not_restart():
    """Eight rejected images whose psi* agree elsewhere, NIS ~200 (the longest nominal run on
    the tuning cities): lost, never restarted."""
    m = DivergenceMonitor()
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 8, 200.0, FAR, True)
    assert verdicts[-1].lost
    assert all(v.restart is None for v in verdicts)


def test_a_strong_contradiction_restarts_at_the_agreeing_images():
    m = DivergenceMonitor()
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 6, 3000.0, FAR, True)
    first = next(i for i, v in enumerate(verdicts) if v.restart is not None)
    assert first == 5  # the 6th: min_rejected (0.75) of the 8-step window
    np.testing.assert_allclose(verdicts[first].restart, FAR, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(verdicts[first].restart_cov) > 0)


def test_a_sustained_contradiction_restarts_whatever_its_nis():
    m = DivergenceMonitor(sustained_steps=12)
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 12, 40.0, FAR, True)
    assert all(v.restart is None for v in verdicts[:11])
    assert verdicts[11].restart is not None


def test_an_accepted_image_breaks_the_sustained_run():
    m = DivergenceMonitor(sustained_steps=12)
    feed(m, 8, 40.0, FAR, True)
    feed(m, 1, 2.0, FAR, False)  # accepted
    assert all(v.restart is None for v in feed(m, 11, 40.0, FAR, True))


SIDEWAYS = np.array([0.0, 1.2, 0.0])  # psi* 1.2 m beside the belief: a shove, not a kidnap


def test_psi_agreeing_a_little_off_the_belief_is_a_drift():
    """Accepted images (NIS 4) whose psi* agree 1.2 m beside the belief: after drift_steps
    of them the verdict names that place, doubtful but not lost; then it needs fresh
    evidence before it fires again."""
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE, drift_steps=4, drift_change=None)
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 8, 4.0, SIDEWAYS, False)
    fired = [i for i, v in enumerate(verdicts) if v.drift is not None]
    assert fired == [3, 7]
    np.testing.assert_allclose(verdicts[3].drift, SIDEWAYS, atol=1e-9)
    assert verdicts[3].doubtful and not verdicts[3].lost and verdicts[3].restart is None
    assert not verdicts[2].doubtful


@pytest.mark.parametrize("psis", [
    [SIDEWAYS, -SIDEWAYS],  # psi* scattered on both sides: no place agreed on
    [FAR],  # 6 m off: the lost and restart tests' case, never a widening towards it
    [SIDEWAYS, SIDEWAYS, SIDEWAYS, NEAR],  # one of the last four agrees with the belief
])
def test_no_drift_without_agreement_a_little_off(psis):
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE, drift_steps=4)
    verdicts = [feed(m, 1, 4.0, psis[t % len(psis)], False)[0] for t in range(16)]
    assert all(v.drift is None for v in verdicts)


def test_one_view_seen_again_at_rest_is_no_drift():
    """Zero controls: the same image again and again, its psi* one error, however often."""
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE, drift_steps=4, drift_change=None)
    assert all(v.drift is None for v in feed(m, 12, 4.0, SIDEWAYS, False, u=(0.0, 0.0)))
    moving = feed(m, 4, 4.0, SIDEWAYS, False)  # moving again: the last view and 3 new ones
    assert [v.drift is not None for v in moving] == [False, False, True, False]


def test_drift_change_fires_on_a_shove_once():
    """psi* agreeing with the belief, then suddenly 1.2 m beside it: the change-only drift
    test fires as the plain one does, and not again while the images keep saying so (the
    run before the recent one is off already)."""
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE, drift_steps=4, drift_change=1.0)
    feed(m, 8, 1.5, NEAR, False)
    verdicts = feed(m, 12, 4.0, SIDEWAYS, False)
    assert [i for i, v in enumerate(verdicts) if v.drift is not None] == [3]
    np.testing.assert_allclose(verdicts[3].drift, SIDEWAYS, atol=1e-9)


@pytest.mark.parametrize("change, fires", [(None, True), (DRIFT_CHANGE, False)])
def test_drift_change_ignores_a_bias_that_grows_slowly(change, fires):
    """psi* moving off the belief by 0.1 m a step (a biased stretch of map, not a shove):
    the plain drift test fires once four values agree beyond its distance, the change-only
    one never does (no run of four lies more than drift_change from the four before)."""
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE, drift_steps=4, drift_change=change)
    feed(m, 8, 1.5, NEAR, False)
    verdicts = [feed(m, 1, 4.0, np.array([0.0, 0.1 * t, 0.0]), False)[0] for t in range(21)]
    assert any(v.drift is not None for v in verdicts) == fires


def test_drift_only_never_says_lost_or_restarts():
    m = DivergenceMonitor(drift_only=True, drift_distance=DRIFT_DISTANCE, drift_change=None)
    verdicts = feed(m, 12, 3000.0, FAR, True) + feed(m, 8, 4.0, SIDEWAYS, False)
    assert not any(v.lost or v.restart is not None for v in verdicts)
    assert any(v.drift is not None for v in verdicts)


def test_drift_test_is_off_by_default_and_switched_on_fires_on_a_change():
    m = DivergenceMonitor()
    assert m.drift_distance is None
    feed(m, 8, 1.5, NEAR, False)
    assert all(v.drift is None for v in feed(m, 12, 4.0, SIDEWAYS, False))
    m = DivergenceMonitor(drift_distance=DRIFT_DISTANCE)
    assert m.drift_change == DRIFT_CHANGE
    feed(m, 8, 1.5, NEAR, False)
    assert any(v.drift is not None for v in feed(m, 12, 4.0, SIDEWAYS, False))


def test_drift_only_without_a_drift_distance_is_refused():
    with pytest.raises(ValueError, match="drift_only=True needs a drift_distance"):
        DivergenceMonitor(drift_only=True)


def test_drift_steps_beyond_the_window_are_refused():
    with pytest.raises(ValueError, match="drift_steps"):
        DivergenceMonitor(window=4, drift_steps=6)
    with pytest.raises(ValueError, match="drift_change needs 2 \\* drift_steps"):
        DivergenceMonitor(window=8, drift_steps=5, drift_change=1.0)


@pytest.mark.parametrize("name, value", [("strong_nis", 0.0), ("strong_steps", 0),
                                         ("sustained_steps", 0), ("doubt_nis", np.nan),
                                         ("drift_distance", 0.0), ("drift_heading", -1.0),
                                         ("drift_steps", 1), ("drift_only", "yes"),
                                         ("drift_change", 0.0)])
def test_bad_settings_are_named(name, value):
    with pytest.raises((ValueError, TypeError), match=name):
        DivergenceMonitor(**{name: value})


# ---------------------------------------------------------------- a restart on trial
START = 60  # the plain EKF accepts every image of the shared drive from here to step 200
def _tracking(localizer, W, drive, **options):
    """A BeliefFilter with ``options`` run on the shared drive (features ``W``) up to START."""
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    _, poses, controls = drive
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model, **options)
    env.close()
    f.reset(W[0], poses[0], P)
    for t in range(1, START):
        f.step(controls[t - 1], W[t])
    return f


def _tracking_then_trial(localizer, drive, incumbent_error: float):
    """A detecting EKF run on the shared drive up to START, then put on trial as a
    divergence restart leaves it; the replaced EKF is ``incumbent_error`` m from where the
    running one is (0: the running one is moved 3 m off instead). Returns the filter and
    the statuses of the next 3 * TRIAL_STEPS steps."""
    from localization.filtering.belief import BeliefFilter
    from localization.filtering.restart_trial import TRIAL_STEPS

    images, poses, controls = drive
    W = localizer.transform(images)
    f = _tracking(localizer, W, drive, detect_divergence=True)
    if incumbent_error:
        other = BeliefFilter(localizer, f.motion_model)
        other.reset(W[START - 1], poses[START - 1] + np.array([incumbent_error, 0.0, 0.0]), P)
        incumbent, misses = other.ekf, 20
    else:
        incumbent, misses = f.ekf, f.misses
        f._start(f.x + np.array([3.0, 0.0, 0.0]), P)  # what a restart at aliased images does
    f._put_on_trial(incumbent, misses)
    f.belief_status = "relocalizing"
    end = START + 3 * TRIAL_STEPS
    statuses = [f.step(controls[t - 1], W[t])[1] for t in range(START, end)]
    return f, statuses, poses[end - 1]


def test_a_restart_the_images_do_not_confirm_is_undone(localizer, drive):
    """A divergence restart at a wrong place (3 m off) with the replaced, right EKF on
    trial beside it: the next images are gated at the wrong place and accepted at the right
    one, so within TRIAL_STEPS measured steps the right EKF comes back ("reverted")."""
    f, statuses, truth = _tracking_then_trial(localizer, drive, incumbent_error=0.0)
    assert "reverted" in statuses, statuses
    assert np.hypot(*(f.x[:2] - truth[:2])) < 0.5


def test_a_restart_the_images_confirm_stands(localizer, drive):
    f, statuses, truth = _tracking_then_trial(localizer, drive, incumbent_error=3.0)
    assert "reverted" not in statuses and f._trial is None, statuses
    assert np.hypot(*(f.x[:2] - truth[:2])) < 0.5


def _coasting(localizer, drive, **options):
    """A BeliefFilter fed 2 * LOST_AFTER_MISSES images off the maps after the drive's first,
    then rejected images (from 12 m on) up to step 40: (filter, [(measurement status,
    belief status, P)] of those steps)."""
    from localization.filtering.belief import LOST_AFTER_MISSES, BeliefFilter
    from tests.localization.conftest import make_env

    images, poses, controls = drive
    W = localizer.transform(images)
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model, **options)
    env.close()
    f.reset(W[0], poses[0], P)
    off_map = W[0] + 100.0 * W.std(axis=0)  # features far from every training image
    for t in range(1, 2 * LOST_AFTER_MISSES):
        assert f.step(controls[t - 1], off_map)[1] == "out_of_domain"
    assert f.misses > LOST_AFTER_MISSES and f.belief_status == "doubtful"
    steps = []
    for t in range(2 * LOST_AFTER_MISSES, 40):
        status = f.step(controls[t - 1], W[t + 120])[1]
        steps.append((status, f.belief_status, f.P))
    return f, steps


def test_misses_are_doubt_while_p_is_narrow_and_lost_once_it_is_wide(localizer, drive):
    """Images off the maps tell nothing: coasting on F the EKF is "doubtful" (the agent
    slows down and drives on), not "lost" (the agent would stop and turn to views the maps
    do not know). Rejected images widen the heading as far as the inflation goes, and that
    alone is still "doubtful"; once the position is too uncertain to steer on (driving on
    an uncertain heading gets there) it is "lost"."""
    from localization.filtering.belief import (
        LOST_HEADING_STD,
        LOST_POSITION_STD,
        MAX_HEADING_STD,
    )

    _, steps = _coasting(localizer, drive)
    assert [s for s, _, _ in steps].count("gated") >= 0.9 * len(steps)  # images 12 m on
    assert MAX_HEADING_STD < LOST_HEADING_STD
    for _, status, cov in steps:
        wide = np.linalg.eigvalsh(cov[:2, :2])[-1] > LOST_POSITION_STD ** 2
        assert status == ("lost" if wide else "doubtful"), (status, cov)
    heading_std = [np.sqrt(cov[2, 2]) for _, status, cov in steps if status == "doubtful"]
    assert max(heading_std) >= MAX_HEADING_STD  # the inflation's cap, still doubtful
    assert steps[-1][1] == "lost"


def test_a_relocalization_at_a_look_alike_is_undone(localizer, drive):
    """After ``relocalize_after`` images off the maps the belief restarts at the next
    image's psi*; that image is from 12 m on (a look-alike), the images after it are the
    robot's own again: they are gated at the restart and fit the belief that coasted, which
    comes back ("reverted") instead of staying 12 m off."""
    from localization.filtering.restart_trial import TRIAL_STEPS

    images, poses, controls = drive
    W = localizer.transform(images)
    n = 2 * TRIAL_STEPS  # relocalize_after: more than a trial lasts
    f = _tracking(localizer, W, drive, relocalize_after=n)
    off_map = W[0] + 100.0 * W.std(axis=0)
    statuses = [f.step(controls[t - 1], off_map)[1] for t in range(START, START + n)]
    statuses.append(f.step(controls[START + n - 1], W[START + n + 120])[1])
    assert statuses == ["out_of_domain"] * n + ["relocalized"], statuses
    assert np.hypot(*(f.x[:2] - poses[START + n][:2])) > 3.0  # at the look-alike
    end = START + n + 1 + 2 * TRIAL_STEPS
    statuses = [f.step(controls[t - 1], W[t])[1] for t in range(START + n + 1, end)]
    assert "reverted" in statuses, statuses
    assert np.hypot(*(f.x[:2] - poses[end - 1][:2])) < 0.5


def _restarted_at_a_look_alike(localizer, drive, n: int = 10):
    """A tracking EKF (``relocalize_after=n``) fed ``n - 1`` images off the maps, then
    restarted at a look-alike view 12 m on. Returns the filter, that view's features and
    the true pose at the restart."""
    images, poses, controls = drive
    W = localizer.transform(images)
    f = _tracking(localizer, W, drive, relocalize_after=n)
    off_map = W[0] + 100.0 * W.std(axis=0)
    for t in range(START, START + n - 1):
        f.step(controls[t - 1], off_map)
    look_alike = W[START + n + 120]
    assert f.step(controls[START + n - 1], look_alike)[1] == "relocalized"
    return f, look_alike, poses[START + n]


def test_a_look_alike_seen_again_and_again_does_not_confirm_a_restart(localizer, drive):
    """The restart's look-alike view, seen again by a robot standing still (zero control),
    agrees with the restart every time; repeated views are not evidence: the restart is
    never confirmed, the belief it replaced comes back after TRIAL_REPEATS of them, and no
    restart is tried again from the same view (stop 34: held-out city 31's stuck robot)."""
    from localization.filtering.restart_trial import TRIAL_REPEATS

    f, look_alike, start = _restarted_at_a_look_alike(localizer, drive)
    steps = [f.step(np.zeros(2), look_alike) for _ in range(TRIAL_REPEATS + 30)]
    statuses = [s for _, s in steps]
    assert statuses.count("accepted") >= 3, statuses  # the old trial's confirmation
    assert statuses.index("reverted") == TRIAL_REPEATS - 1, statuses
    assert "relocalized" not in statuses, statuses
    assert np.hypot(*(f.x[:2] - start[:2])) < 1.0


def test_commanded_turns_while_pinned_do_not_confirm_a_restart(localizer, drive):
    """A robot pinned against a building while its pilot commands a full turn: each contact
    step is predicted as blocked with the commanded turn, whose standard deviation is as
    large as itself, so it is no evidence of a new view. The look-alike seen again and
    again does not confirm the restart; the belief it replaced comes back after
    TRIAL_REPEATS (held-out city 31, stop 41: confirmed 22 m off in three steps)."""
    from localization.filtering.restart_trial import TRIAL_REPEATS, VIEW_TURN

    f, look_alike, start = _restarted_at_a_look_alike(localizer, drive)
    turn = np.array([0.18, 1.0])
    assert f.motion_model.predict(np.zeros(3), f.gain * turn)[2] >= VIEW_TURN
    statuses = [f.step(turn, look_alike, contact=("city",))[1] for _ in range(3)]
    assert "out_of_domain" not in statuses and f._trial is not None
    assert (f._trial.steps, f._trial.repeats) == (0, 3)  # repeats, not views
    statuses += [f.step(turn, look_alike, contact=("city",))[1]
                 for _ in range(TRIAL_REPEATS + 2)]
    assert statuses.index("reverted") == TRIAL_REPEATS - 1, statuses
    assert "relocalized" not in statuses, statuses
    assert np.hypot(*(f.x[:2] - start[:2])) < 1.0


def test_a_trial_counts_views_from_somewhere_else_only():
    from localization.filtering.restart_trial import (
        CONFIRM_STEPS,
        TRIAL_REPEATS,
        VIEW_TRAVEL,
        VIEW_TURN,
        RestartTrial,
    )

    trial = RestartTrial(None, 0)
    for _ in range(TRIAL_REPEATS - 1):
        assert not trial.record("accepted", 0.0, 0.0)
    assert trial.accepted == 0 and not trial.failed
    assert not trial.record("out_of_domain", VIEW_TRAVEL, 0.0)  # tells nothing, carries on
    assert trial.record("accepted", 0.0, 0.0)  # the odometry since the last view counts
    assert not trial.record("accepted", VIEW_TRAVEL / 2, VIEW_TURN / 2)
    assert trial.record("accepted", VIEW_TRAVEL / 2, VIEW_TURN / 2)
    assert trial.record("accepted", 0.0, VIEW_TURN)  # a turn on the spot is a new view
    assert trial.accepted == CONFIRM_STEPS and trial.confirmed and not trial.failed
    stuck = RestartTrial(None, 0)
    for _ in range(TRIAL_REPEATS):
        stuck.record("accepted", 0.0, 0.0)
    assert stuck.stalled and stuck.failed


def test_a_start_off_the_maps_relocalizes_with_nothing_to_come_back_to(localizer, drive):
    """A belief that never had a place (started from the prior: the first image off the
    maps) has nothing to come back to: its relocalization's trial holds no replaced EKF."""
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    images, _, controls = drive
    W = localizer.transform(images)
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model)
    env.close()
    assert f.reset(W[0] + 100.0 * W.std(axis=0)) == "out_of_domain"
    assert f.step(controls[0], W[1])[1] == "relocalized" and f._trial.replaced is None


def _start_from(localizer, drive, first: int, steps: int):
    """A BeliefFilter started from image ``first`` of the drive, then fed the drive's own
    images 1..steps; returns the filter, its measurement statuses and its belief statuses
    (after reset, then after each step)."""
    from localization.filtering.belief import BeliefFilter
    from tests.localization.conftest import make_env

    images, _, controls = drive
    W = localizer.transform(images)
    env = make_env()
    f = BeliefFilter(localizer, env.unwrapped.motion_model)
    env.close()
    f.reset(W[first])
    statuses, beliefs = [], [f.belief_status]
    for t in range(1, steps + 1):
        statuses.append(f.step(controls[t - 1], W[t])[1])
        beliefs.append(f.belief_status)
    return f, statuses, beliefs


def test_a_start_from_one_image_is_relocalizing_until_the_images_confirm_it(localizer, drive):
    """psi* of the first image is a guess: the belief is "relocalizing" until CONFIRM_STEPS
    measurements since its last (re)start were accepted (this small map's first psi* is
    0.75 m off, gated, and the belief starts again at a later image), then "tracking"."""
    from localization.filtering.restart_trial import CONFIRM_STEPS, TRIAL_STEPS

    _, poses, _ = drive
    n = 4 * TRIAL_STEPS
    f, statuses, beliefs = _start_from(localizer, drive, 0, n)
    last = max((t for t, s in enumerate(statuses) if s == "relocalized"), default=-1)
    accepted = np.cumsum([s == "accepted" for s in statuses[last + 1:]])
    confirmed = last + 1 + int(np.searchsorted(accepted, CONFIRM_STEPS))
    assert beliefs[0] == "relocalizing" and confirmed < n, statuses
    assert set(beliefs[:confirmed + 1]) == {"relocalizing"}, beliefs
    assert set(beliefs[confirmed + 1:]) == {"tracking"}, beliefs
    assert "reverted" not in statuses and f._trial is None
    assert np.hypot(*(f.x[:2] - poses[n][:2])) < 0.5


def test_a_start_at_a_look_alike_starts_again_at_a_later_image(localizer, drive):
    """The first image's psi* is a place 12 m on (a look-alike); the images after it are the
    robot's own and are gated there: within TRIAL_STEPS measured steps the belief starts
    again at the current image's psi*, long before the 50-step restart."""
    from localization.filtering.restart_trial import TRIAL_STEPS

    _, poses, _ = drive
    n = 4 * TRIAL_STEPS
    f, statuses, beliefs = _start_from(localizer, drive, 120, n)
    assert "relocalized" in statuses[:TRIAL_STEPS], statuses
    assert np.hypot(*(f.x[:2] - poses[n][:2])) < 0.5
    assert beliefs[-1] == "tracking"


@pytest.mark.parametrize("shift, change", [(1.2, None), (-1.0, None), (1.2, DRIFT_CHANGE),
                                           (-1.4, DRIFT_CHANGE)])
def test_a_belief_shoved_beside_the_truth_is_widened_back(localizer, drive, shift, change):
    """The belief moved ``shift`` m sideways at START (what a push does to the robot, the
    other way round): the representation measurements still pass the gate and, with P 0.1 m
    wide, move it a centimetre a step (0.9 m off ten steps later, measured); the drift test
    widens P towards psi* and the images bring it back (0.1 m, measured), also when it
    fires on a sudden change of psi*'s offset only (``drift_change``, the default; the
    shifts beyond it)."""
    images, poses, controls = drive
    W = localizer.transform(images)
    errors = {}
    for name, detect in (("drift", {"drift_distance": DRIFT_DISTANCE, "drift_change": change}),
                         ("no drift", {"drift_distance": None})):
        f = _tracking(localizer, W, drive, detect_divergence=detect)
        yaw = f.ekf.x[2]
        f.ekf.x = f.ekf.x + shift * np.array([-np.sin(yaw), np.cos(yaw), 0.0])
        for t in range(START, START + 10):
            f.step(controls[t - 1], W[t])
        errors[name] = float(np.hypot(*(f.x[:2] - poses[START + 9][:2])))
    assert errors["drift"] < 0.3 and errors["no drift"] > 0.6, errors
