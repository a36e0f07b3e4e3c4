"""ParticleBelief: vectorised F, log-weights, resampling, modes, recovery, seeds, bad inputs.

The unit tests use the small city-0 localizer of ``tests/localization/conftest.py``; the
recovery tests fit a street-wide one on city 11 (never used to choose any default).
"""

from __future__ import annotations

import numpy as np
import pytest

import envs  # noqa: F401
from envs.motion_model import UnicycleModel
from localization.filtering._modes import circular_mean, find_modes
from localization.filtering.particle_motion import is_unicycle, predict_particles, unicycle_step
from localization.filtering.particles import PARTICLE_STATUSES, ParticleBelief
from localization.geometry import wrap_angle

from ..conftest import held_out_localizer

DT = 0.1


def _belief(localizer, **kw) -> ParticleBelief:
    return ParticleBelief(localizer, UnicycleModel(DT), **{"n_particles": 500, "seed": 0, **kw})


# ---------------------------------------------------------------- motion model
def test_vectorised_unicycle_equals_F_per_particle():
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-9, 9, (300, 2)), rng.uniform(-np.pi, np.pi, 300)])
    U = np.column_stack([rng.uniform(-1, 1, 300), rng.uniform(-1, 1, 300)])
    U[::7, 1] = 0.0
    U[1::7, 1] = 3e-7  # the small-w expansion
    F = UnicycleModel(DT)
    want = np.array([F.predict(x, u) for x, u in zip(X, U)])
    got = unicycle_step(X, U, DT)
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(got[:, 2] - want[:, 2]), 0.0, atol=1e-12)
    np.testing.assert_allclose(predict_particles(F, X, U[0]),
                               [F.predict(x, U[0]) for x in X], atol=1e-12)


def test_other_motion_models_are_looped_not_assumed_unicycle():
    class Skid(UnicycleModel):
        def predict(self, pose, u):
            return super().predict(pose, np.asarray(u) * [0.5, 1.0])

    F = Skid(DT)
    assert is_unicycle(UnicycleModel(DT)) and not is_unicycle(F)
    X = np.array([[0.0, 0.0, 0.3], [1.0, 2.0, -2.0]])
    np.testing.assert_allclose(predict_particles(F, X, [0.8, 0.2]),
                               [F.predict(x, [0.8, 0.2]) for x in X])


# ---------------------------------------------------------------- weights
def test_all_likelihoods_underflowing_give_no_nan(localizer, features):
    W, poses, _ = features
    pf = _belief(localizer, max_injection=0.0)
    pf.reset(W[0], x0=poses[0])
    far = poses[0] + [40.0, -35.0, 2.0]  # outside the map: R* is NaN there
    pf.particles = np.tile(far, (pf.n_particles, 1)) + np.random.default_rng(1).normal(
        0.0, 0.5, (pf.n_particles, 3))
    assert np.all(np.isnan(pf.distances(W[1])))
    pf.step([0.0, 0.0], W[1])
    assert np.all(np.isfinite(pf.log_weights)) and pf.weights.sum() == pytest.approx(1.0)
    assert np.all(np.isfinite(pf.pose_mean)) and np.all(np.isfinite(pf.pose_cov))
    # in the map, turned around, with prior weights whose products with the likelihoods
    # underflow to 0 in linear space (a linear normalisation would give 0 / 0 = NaN)
    pf.reset(W[0], x0=poses[0])
    pf.particles = pf.particles + [0.0, 0.0, np.pi]
    pf.log_weights = np.full(pf.n_particles, -800.0)
    d2 = pf.distances(W[1])
    assert np.isfinite(d2).any()
    assert np.sum(np.exp(pf.log_weights) * np.exp(-0.5 * np.nan_to_num(d2, nan=0.0))) == 0.0
    pf.step([0.0, 0.0], W[1])
    assert np.all(np.isfinite(pf.log_weights)) and pf.weights.sum() == pytest.approx(1.0)


def test_a_start_from_one_image_is_ambiguous_until_the_images_confirm_it(localizer, features):
    """One image's proposals are a guess: with ``confirm_steps`` 2 no single image confirms
    their mode, so a start from the image alone says "ambiguous" (as a step would), not
    "tracking"; a given pose is "tracking", a global start "relocalizing"."""
    W, poses, _ = features
    pf = _belief(localizer)
    pf.reset(W[0])
    assert not pf.confirmed and pf.belief_status == "ambiguous"
    pf.reset(W[0], x0=poses[0])
    assert pf.belief_status == "tracking"
    pf.reset(W[0], mode="global")
    assert pf.belief_status == "relocalizing"
    one = _belief(localizer, confirm_steps=1, confirm_share=0.0, confident_weight=1e-9)
    one.reset(W[0])
    assert one.confirmed and one.belief_status == "tracking"  # the rule, not a constant


def test_resampling_fires_when_the_effective_sample_size_drops(localizer, features):
    W, poses, controls = features
    calls = []

    def counting(w):
        from filterpy.monte_carlo import systematic_resample
        calls.append(len(w))
        return systematic_resample(w)

    pf = _belief(localizer, resample=counting, max_injection=0.0)
    pf.reset(W[0], x0=poses[0])
    half = pf.n_particles // 2
    pf.particles[:half] += [3.0, 0.0, 0.0]  # half the particles 3 m off
    pf.step(controls[0], W[1])
    assert calls == [pf.n_particles]  # the far half lost its weight: ESS < N / 2
    assert np.allclose(pf.weights, 1.0 / pf.n_particles)
    assert np.hypot(*(pf.pose_mean[:2] - poses[1][:2])) < 0.5
    lazy = _belief(localizer, resample=counting, resample_threshold=1e-6, max_injection=0.0)
    lazy.reset(W[0], x0=poses[0])
    lazy.step(controls[0], W[1])
    assert len(calls) == 1 and lazy.ess < lazy.n_particles  # weighted, not resampled


def test_a_blocked_contact_holds_the_particles_and_spreads_them_by_the_step(localizer, features):
    """As the EKF's: no translation, the commanded step as one standard deviation."""
    W, poses, _ = features
    u = np.array([1.0, 0.0])
    moved, held, commanded = (_belief(localizer, contact_motion=m) for m in
                              ("blocked", "blocked", "commanded"))
    for pf in (moved, held, commanded):
        pf.reset(W[0], x0=poses[0])
    start = held.particles.copy()
    moved.predict(u)
    held.predict(u, contact=True)
    commanded.predict(u, contact=True)
    np.testing.assert_array_equal(moved.particles, commanded.particles)  # same draws
    step = DT * localizer.control_gain_[0]
    shift = np.mean(held.particles[:, :2] - start[:, :2], axis=0)
    assert np.hypot(*shift) < 0.2 * step  # held on the spot (the mean of the draws)
    assert np.hypot(*(np.mean(moved.particles[:, :2] - start[:, :2], axis=0))) > 0.8 * step
    spread = np.std(held.particles[:, :2] - start[:, :2], axis=0)
    assert np.all(spread > 0.8 * step)  # the step is one standard deviation, both axes
    assert held.contact_motion == "blocked"
    with pytest.raises(ValueError, match="contact_motion"):
        _belief(localizer, contact_motion="slide")


class _Wall:
    """A free_space with a building at x > ``edge``."""

    def __init__(self, edge: float) -> None:
        self.edge = edge

    def __call__(self, points: np.ndarray, margin: float) -> np.ndarray:
        return points[:, 0] < self.edge - margin


def test_a_contact_weighs_the_particles_by_the_map_at_the_touched_side(localizer, features):
    """Particles facing east, half of them at a wall ahead: a bump ahead moves the weight to
    those (CONTACT_MISS for the rest); a bump behind is explained by none, and with 95 % of
    the weight in the open the belief is "lost" for CONTACT_LOST_STEPS steps."""
    from localization.filtering.map_contact import CONTACT_LOST_STEPS, CONTACT_MISS

    W, poses, _ = features
    pf = _belief(localizer, free_space=_Wall(0.3), track_mode=False)
    pf.reset(W[0], x0=poses[0])
    X = np.zeros((500, 3))
    X[:250, 0] = 0.1  # rim 0.32: at the wall (slack 0.1)
    X[250:, 0] = -2.0
    pf._set(X)
    pf.step(np.zeros(2), W[1], contact=("city",), bearing=0.0)
    at_wall = pf.particles[:, 0] > -1.0
    ratio = pf.weights[at_wall].mean() / pf.weights[~at_wall].mean()
    assert ratio > 0.5 / CONTACT_MISS and pf.status != "lost"
    pf._set(X)
    pf.step(np.zeros(2), W[1], contact=("city",), bearing=np.pi)
    statuses = [pf.status]
    for t in range(CONTACT_LOST_STEPS):
        pf.step(np.zeros(2), W[1])
        statuses.append(pf.status)
    assert statuses[:CONTACT_LOST_STEPS] == ["lost"] * CONTACT_LOST_STEPS
    assert statuses[-1] != "lost" or pf.amcl.w_fast < pf.lost_ratio * pf.amcl.w_slow


def test_capped_log_likelihood_floors_nan_at_the_gate_or_the_given_value():
    from localization.filtering.particle_likelihood import capped_log_likelihood

    d2 = np.array([1.0, 20.0, np.nan, np.nan])
    np.testing.assert_array_equal(capped_log_likelihood(d2, 14.0), [-0.5, -7.0, -7.0, -7.0])
    np.testing.assert_array_equal(
        capped_log_likelihood(d2, 14.0, np.array([0.0, 0.0, 3.0, np.inf])),
        [-0.5, -7.0, -1.5, -7.0])


def test_unmapped_street_poses_score_as_typical_and_buildings_at_the_floor(localizer, features):
    """Particles where the route map has no R*(theta): the gate's floor by default; with
    unmapped="typical" a free one scores d2 = dof (3), one inside a building the floor, and
    a particle on the map what it scored before."""
    W, poses, _ = features
    X = np.array([poses[0], [30.0, 0.0, 0.0], [40.0, 0.0, 0.0]])
    floor, typical = (_belief(localizer, track_mode=False, free_space=_Wall(35.0),
                              unmapped=u) for u in ("floor", "typical"))
    z = floor.likelihood.measure(W[0])
    d2 = floor.distances(W[0], X)
    assert np.isfinite(d2[0]) and np.isnan(d2[1:]).all()
    for pf in (floor, typical):
        pf.reset(W[0], x0=poses[0])
        pf._set(X)
    np.testing.assert_allclose(floor._log_likelihood(z), [-0.5 * min(d2[0], floor.gate),
                                                          -0.5 * floor.gate, -0.5 * floor.gate])
    np.testing.assert_allclose(typical._log_likelihood(z), [-0.5 * min(d2[0], floor.gate),
                                                            -1.5, -0.5 * floor.gate])


def test_without_a_map_or_with_traffic_a_contact_weighs_nothing(localizer, features):
    """A map that has room everywhere ahead (every particle's touched point is free): a
    bump into the city weighs the particles and makes the belief "lost" (without the
    spread of test_contact_spread.py the particles are those of the run without the map);
    the same bump without a map, or a bump into traffic with the map, leaves particles
    and weights those of the same seeded run without the map."""
    W, poses, controls = features

    def run(free_space, contact, spread=0.5):
        pf = _belief(localizer, free_space=free_space, track_mode=False, contact_spread=spread)
        pf.reset(W[0], x0=poses[0])
        pf.step(controls[0], W[1], contact=contact, bearing=0.0)
        return pf

    room = _Wall(1e9)
    weighed, plain = run(room, ("city",), spread=0.0), run(None, ("city",))
    np.testing.assert_array_equal(weighed.particles, plain.particles)  # same draws
    assert weighed.status == "lost" and plain.status != "lost"
    assert run(room, ("city",)).status == "lost"
    for free_space, contact in ((room, ("traffic",)), (None, ("city",))):
        pf, without = run(free_space, contact), run(None, contact)
        np.testing.assert_array_equal(pf.particles, without.particles)
        np.testing.assert_array_equal(pf.log_weights, without.log_weights)
        assert pf.status == without.status != "lost"
    with pytest.raises(TypeError, match="free_space must be None or a callable"):
        _belief(localizer, free_space=np.ones(3))


# ---------------------------------------------------------------- modes
def test_a_belief_coasting_on_images_without_a_measurement_says_so(localizer, features,
                                                                   drive):
    """Images with no measurement (an occluded or unfamiliar view) only move the particles:
    the belief keeps "tracking" for LOST_AFTER_MISSES - 1 such steps, is "doubtful" from the
    next (as the EKF), "ambiguous" once its dominant mode is light, and an image with a
    measurement gives it the step's status again. Before, it said "tracking" throughout."""
    from localization.filtering.belief import LOST_AFTER_MISSES

    W, poses, _ = features
    black = localizer.transform(np.zeros_like(drive[0][:1]))[0]
    assert not np.all(np.isfinite(localizer.measure(black, "representation")))
    pf = _belief(localizer, max_injection=0.0, track_mode=False)
    pf.reset(W[0], x0=poses[0])
    assert pf.belief_status == "tracking"
    coasting = []
    for _ in range(LOST_AFTER_MISSES + 1):
        assert pf.step([0.0, 0.0], black)[1] == "out_of_domain"
        coasting.append(pf.belief_status)
    assert coasting == ["tracking"] * (LOST_AFTER_MISSES - 1) + ["doubtful"] * 2
    pf.particles[::2] += [3.0, 0.0, 0.0]  # two hypotheses of equal weight
    pf.step([0.0, 0.0], black)
    assert pf.belief_status == "ambiguous"
    _, status = pf.step([0.0, 0.0], W[0])
    assert pf.belief_status == status != "out_of_domain"


def test_dominant_mode_summary_of_two_modes_is_the_heavier_one(localizer, features):
    rng = np.random.default_rng(0)
    a, b = np.array([1.0, 2.0, 0.5]), np.array([7.0, 2.0, 0.5])
    X = np.vstack([a + rng.normal(0, [0.2, 0.2, 0.05], (700, 3)),
                   b + rng.normal(0, [0.2, 0.2, 0.05], (300, 3))])
    modes = find_modes(X, np.ones(len(X)))
    assert len(modes) >= 2
    np.testing.assert_allclose(modes[0].mean, a, atol=0.05)
    np.testing.assert_allclose(modes[1].mean, b, atol=0.05)
    assert modes[0].weight == pytest.approx(0.7, abs=0.02)
    assert modes[1].weight == pytest.approx(0.3, abs=0.02)
    assert np.sqrt(modes[0].cov[0, 0]) < 0.3  # not the spread of both modes (3 m)
    # through the filter: weights, not counts, decide which mode dominates (the particles'
    # own summary: track_mode's EKF would hold its hypothesis, test_mode_tracker.py)
    W = features[0]
    pf = _belief(localizer, n_particles=len(X), track_mode=False)
    pf.reset(W[0])
    pf._set(X, np.log(np.where(np.arange(len(X)) < 700, 0.2, 1.0)))
    np.testing.assert_allclose(pf.pose_mean, b, atol=0.05)
    hyp = pf.hypotheses
    assert hyp["weights"][0] > 0.6 and hyp["means"].shape[1] == 3


def test_image_seeded_modes_stay_ambiguous_until_an_image_agrees(localizer, features):
    """A hypothesis seeded from images may be a place that merely looks alike: the status
    says "ambiguous" until an image's retrieved neighbours agree with it."""
    W, poses, _ = features
    k = 20  # its image's neighbours agree (7 of 10 within 1 m); the drive's first do not
    far = int(np.argmax(np.hypot(*(poses[:, :2] - poses[k, :2]).T) > 3.0))
    pf = _belief(localizer, max_injection=0.0, track_mode=False)
    pf.reset(W[k], x0=poses[k])
    assert pf.confirmed  # a given start pose needs no image to confirm it
    rng = np.random.default_rng(2)
    pf.confirmation.withdraw()  # as after an injection
    for centre, confirmed in ((poses[far], False), (poses[far], False), (poses[k], False),
                              (poses[k], True)):  # confirm_steps=2 agreeing frames in a row
        pf._set(centre + rng.normal(0.0, [0.05, 0.05, 0.01], (pf.n_particles, 3)))
        _, status = pf.step([0.0, 0.0], W[k])
        assert pf.confirmed is confirmed
        assert status == ("tracking" if confirmed else "ambiguous")
    assert pf._proposals.agreement(W[k], poses[far], 1.0, 2.0) == 0.0


def test_unconfirmed_modes_keep_drawing_from_the_images_proposals(localizer, features):
    """Augmented MCL injects only while the likelihood falls; a wrong twin does not make it
    fall. While unconfirmed, ``ambiguous_injection`` of the particles come from the image's
    proposals every step, without calling it relocalizing or restarting the confirmation;
    once confirmed, none do."""
    W, poses, _ = features
    k = 20  # its image's neighbours agree with poses[k] (see the test above)
    pf = _belief(localizer, max_injection=0.0, ambiguous_injection=0.2, track_mode=False)
    pf.reset(W[k], x0=poses[k])
    pf.confirmation.withdraw()  # as after an injection
    rng = np.random.default_rng(3)
    pf._set(poses[k] + rng.normal(0.0, [0.05, 0.05, 0.01], (pf.n_particles, 3)))
    _, status = pf.step([0.0, 0.0], W[k])
    assert 0.1 * pf.n_particles < pf.injected < 0.3 * pf.n_particles
    assert status == "ambiguous" and not pf.confirmed and pf.confirmation.agreeing == 1
    _, status = pf.step([0.0, 0.0], W[k])
    assert pf.confirmed and status == "tracking"
    pf.step([0.0, 0.0], W[k])
    assert pf.injected == 0


def test_a_confirmed_mode_the_images_stop_agreeing_with_loses_it(localizer, features):
    """``unconfirm_steps`` frames in a row whose neighbours point elsewhere withdraw the
    confirmation: the status says "ambiguous" again and the steady injection resumes."""
    W, poses, _ = features
    k = 20
    far = int(np.argmax(np.hypot(*(poses[:, :2] - poses[k, :2]).T) > 3.0))
    pf = _belief(localizer, max_injection=0.0, unconfirm_steps=3, track_mode=False)
    pf.reset(W[k], x0=poses[k])
    rng = np.random.default_rng(4)
    for step, confirmed in enumerate((True, True, False)):  # W[k] does not point at far
        pf._set(poses[far] + rng.normal(0.0, [0.05, 0.05, 0.01], (pf.n_particles, 3)))
        _, status = pf.step([0.0, 0.0], W[k])
        assert pf.confirmed is confirmed, step
    assert status == "ambiguous" and pf.injected == 0  # injection starts next step
    never = _belief(localizer, max_injection=0.0, unconfirm_steps=None, track_mode=False)
    never.reset(W[k], x0=poses[k])
    for _ in range(4):
        never._set(poses[far] + rng.normal(0.0, [0.05, 0.05, 0.01], (pf.n_particles, 3)))
        never.step([0.0, 0.0], W[k])
    assert never.confirmed


def test_mode_summary_goes_down_to_min_mode_weight(localizer, features):
    """Sixteen places, one holding 0.27 % of the weight: listed above ``min_mode_weight``."""
    W, poses, _ = features
    pf = _belief(localizer, n_particles=1600, track_mode=False)
    pf.reset(W[0], x0=poses[0])
    X = np.repeat(np.column_stack([np.arange(16) * 5.0, np.zeros(16), np.zeros(16)]), 100, 0)
    log_w = np.log(np.where(np.arange(1600) < 100, 0.04, 1.0))  # place 0: 0.27 % of the weight
    pf._set(X, log_w)
    assert len(pf.hypotheses["weights"]) == 16
    assert pf.hypotheses["weights"][-1] == pytest.approx(0.04 / 15.04)
    pf.min_mode_weight = 0.01
    pf._set(X, log_w)
    assert len(pf.hypotheses["weights"]) == 15


def test_heading_mean_near_pi_is_on_the_circle():
    rng = np.random.default_rng(0)
    yaw = wrap_angle(np.pi + rng.normal(0.0, 0.05, 2000))  # half near +pi, half near -pi
    assert np.abs(wrap_angle(circular_mean(yaw) - np.pi)) < 0.01
    X = np.column_stack([rng.normal(0, 0.1, 2000), rng.normal(0, 0.1, 2000), yaw])
    mode = find_modes(X, np.ones(2000))[0]
    assert mode.weight > 0.99
    assert np.abs(wrap_angle(mode.mean[2] - np.pi)) < 0.01
    assert mode.cov[2, 2] == pytest.approx(0.05 ** 2, rel=0.2)


# ---------------------------------------------------------------- runs
def test_same_seed_same_run(localizer, features):
    W, poses, controls = features
    a = _belief(localizer, seed=5).run(W[:40], controls[:39], x0=poses[0])
    b = _belief(localizer, seed=5).run(W[:40], controls[:39], x0=poses[0])
    c = _belief(localizer, seed=6).run(W[:40], controls[:39], x0=poses[0])
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert a[2] == b[2]
    assert not np.array_equal(a[0], c[0])


def test_tracks_the_drive_it_was_fitted_with(localizer, features):
    """Without injections (the core filter). Measured on these 120 steps: RMSE 0.22 m (the
    EKF BeliefFilter: 0.14 m); with the default injections 0.56 m, from one transient jump
    to an aliased proposal (2.6 m) around step 50 (reported in issue 12's work)."""
    W, poses, controls = features
    W, poses, controls = W[:121], poses[:121], controls[:120]
    means, _covs, statuses = _belief(localizer, n_particles=1000, max_injection=0.0).run(
        W, controls, x0=poses[0])
    err = np.hypot(*(means[:, :2] - poses[:, :2]).T)
    assert np.sqrt(np.mean(err ** 2)) < 0.35, err.max()
    assert set(statuses) <= set(PARTICLE_STATUSES)


# ---------------------------------------------------------------- bad inputs
@pytest.mark.parametrize("kwargs, error, match", [
    ({"n_particles": 0}, ValueError, "n_particles"),
    ({"n_particles": -5}, ValueError, "n_particles"),
    ({"n_particles": 2.5}, ValueError, "n_particles"),
    ({"measurement": "laser"}, ValueError, "measurement"),
    ({"resample_threshold": 0.0}, ValueError, "resample_threshold"),
    ({"alpha_slow": 0.5, "alpha_fast": 0.1}, ValueError, "alpha_slow"),
    ({"max_injection": 1.5}, ValueError, "max_injection"),
    ({"sample_free": 3}, TypeError, "sample_free"),
    ({"proposal_noise": np.eye(2)}, ValueError, "proposal_noise"),
    ({"confirm_share": 1.5}, ValueError, "confirm_share"),
    ({"confirm_steps": 0}, ValueError, "confirm_steps"),
    ({"max_modes": 0}, ValueError, "max_modes"),
    ({"min_mode_weight": 0.0}, ValueError, "min_mode_weight"),
    ({"min_mode_weight": 1.0}, ValueError, "min_mode_weight"),
    ({"ambiguous_injection": 1.5}, ValueError, "ambiguous_injection"),
    ({"unconfirm_steps": 0}, ValueError, "unconfirm_steps"),
    ({"unmapped": "zero"}, ValueError, "unmapped"),
    ({"unmapped": "typical"}, ValueError, "free_space"),
])
def test_bad_arguments_raise_clear_errors(localizer, kwargs, error, match):
    with pytest.raises(error, match=match):
        _belief(localizer, **kwargs)


def test_bad_inputs_raise_clear_errors(localizer, features):
    W, _poses, _ = features
    pf = _belief(localizer)
    with pytest.raises(RuntimeError, match="reset"):
        pf.step([0.1, 0.0], W[1])
    with pytest.raises(ValueError, match="w "):
        pf.reset(W[0][:3])
    with pytest.raises(ValueError, match="mode"):
        pf.reset(W[0], mode="everywhere")
    pf.reset(W[0])
    with pytest.raises(ValueError, match="u "):
        pf.step([np.nan, 0.0], W[1])
    with pytest.raises(ValueError, match="u "):
        pf.step([0.1, 0.0, 0.0], W[1])
    with pytest.raises(ValueError, match="NaN"):
        pf.step([0.1, 0.0], np.full_like(W[1], np.nan))
    bad = _belief(localizer, sample_free=lambda n, rng: np.zeros((n, 2)))
    with pytest.raises(ValueError, match="sample_free"):
        bad.reset(W[0], mode="global")


# ---------------------------------------------------------------- held-out city
HELD_OUT = 17  # never used to choose a default (tuning cities: 11-14)
RECOVERY_BOUND = 30  # steps; measured (seeds 100-109, this localizer): median 4.5, 9 of 10 <= 30


@pytest.fixture(scope="module")
def held_out():
    env, loc = held_out_localizer(HELD_OUT)
    yield env, loc
    env.close()


def test_kidnapped_robot_is_recovered_on_a_held_out_city(held_out):
    """Teleported more than 5 m after 60 steps, the filter not told; the particle filter
    recovers within 3 steps (measured on this drive)."""
    from localization.workflows.kidnap_eval import record_kidnap_drive, run_filter, steps_to_recover
    env, loc = held_out
    drive = record_kidnap_drive(env, loc, 60, 60, seed=100)
    assert np.hypot(*(drive.poses[drive.kidnap, :2] - drive.poses[drive.kidnap - 1, :2])) > 5
    means, _, statuses = run_filter("particles", drive, loc, env.unwrapped.motion_model, seed=100)
    err = np.hypot(*(means[:, :2] - drive.poses[:, :2]).T)
    assert err[drive.kidnap] > 5.0  # the kidnap did throw the belief off
    steps = steps_to_recover(means, drive.poses, drive.kidnap)
    assert steps is not None and steps <= RECOVERY_BOUND, steps
    assert {"relocalizing", "lost"} & set(statuses[drive.kidnap:drive.kidnap + 5])


def test_global_start_is_localized_on_a_held_out_city(held_out):
    from localization.filtering.free_space import city_sampler
    from localization.workflows.kidnap_eval import record_kidnap_drive, steps_to_recover
    env, loc = held_out
    drive = record_kidnap_drive(env, loc, 60, 0, seed=202)
    pf = ParticleBelief(loc, env.unwrapped.motion_model, seed=202,
                        sample_free=city_sampler(env.unwrapped.city))
    means, _, _ = pf.run(drive.W, drive.controls, mode="global")
    steps = steps_to_recover(means, drive.poses, 0)
    assert steps is not None and steps <= RECOVERY_BOUND, steps


# ---------------------------------------------------------------- look-alike city
LOOKALIKE = 25  # never used to choose a default


def test_global_start_in_the_look_alike_city_does_not_commit_to_a_wrong_twin():
    """City 25 repeats one block; single images cannot tell the twins apart. Measured over
    global starts with seeds 300-307 on this localizer: the longest stretch reported on a
    wrong twin 0-17 steps (issue 12's bound: 20), 0-1 of them with the status "tracking";
    the status "ambiguous" on all 80 steps (no image confirmed a place)."""
    import warnings

    import gymnasium as gym

    from localization.filtering.free_space import city_sampler
    from localization.workflows.benchmarks.global_loc import WRONG_TWIN_STEPS, wrong_twin_run
    from localization.workflows.kidnap_eval import record_kidnap_drive
    from localization.workflows.tracking import fit_city_localizer

    env = gym.make("AppearanceNav-v0", scene_seed=LOOKALIKE, city_layout="lookalike",
                   image_size=(32, 32), motion_noise=0.05, max_episode_steps=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the localizer is poor here by design (aliasing)
        loc, _ = fit_city_localizer(
            env, n_train=8000, lanes="streets", n_drive=300, seed=0,
            localizer_params={"features_params": {"n_components": 16}},
            calibrate_on_belief=False, measurements=("representation",))
    city = env.unwrapped.city
    drive = record_kidnap_drive(env, loc, 80, 0, seed=300)
    pf = ParticleBelief(loc, env.unwrapped.motion_model, seed=300,
                        sample_free=city_sampler(city))
    means, _, statuses = pf.run(drive.W, drive.controls, mode="global")
    env.close()
    assert len(city.twin_shifts(drive.poses[0, :2])) > 0  # the start does have twins
    assert wrong_twin_run(means, drive.poses, city, 0) <= WRONG_TWIN_STEPS
    assert statuses.count("ambiguous") >= 10  # it says it is torn, measured 80

