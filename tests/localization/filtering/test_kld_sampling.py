"""KLD-sampling: Fox's bound, the bins it counts, and the particle belief's adaptive count."""

from __future__ import annotations

import numpy as np
import pytest

import envs  # noqa: F401
from envs.motion_model import UnicycleModel
from localization.filtering.kld_sampling import KLDSampling, kld_sample_size, occupied_bins
from localization.filtering.particles import ParticleBelief


def test_fox_bound_by_hand():
    # k = 2, epsilon 0.05, z = 2.3263 (0.99): 10 (1 - 2/9 + sqrt(2/9) z)^3 = 65.86
    assert kld_sample_size(2) == 66
    # k = 101: 1000 (1 - 2/900 + sqrt(2/900) 2.3263)^3 = 1000 * 1.10744^3 = 1358.2
    assert kld_sample_size(101) == 1359
    assert kld_sample_size(1) == 1 and kld_sample_size(0) == 1
    sizes = [kld_sample_size(k) for k in range(2, 300)]
    assert np.all(np.diff(sizes) > 0)
    assert kld_sample_size(101, epsilon=0.1) < kld_sample_size(101) < kld_sample_size(
        101, confidence=0.999)


def test_bins_are_half_a_metre_and_ten_degrees():
    one = np.array([[0.1, 0.1, 0.01], [0.4, 0.3, 0.1], [0.2, 0.45, 0.15]])
    assert occupied_bins(one) == 1
    apart = np.array([[0.1, 0.1, 0.0], [0.6, 0.1, 0.0], [0.1, 0.6, 0.0], [0.1, 0.1, 0.2]])
    assert occupied_bins(apart) == 4
    assert occupied_bins(np.zeros((0, 3))) == 0


def test_a_compact_set_thins_to_the_minimum_and_a_spread_one_grows():
    rng = np.random.default_rng(0)
    kld = KLDSampling(100, 3000)
    compact = rng.normal([5.25, 5.25, 0.5], [0.02, 0.02, 0.01], size=(1000, 3))
    fresh = np.zeros(1000, dtype=bool)
    fresh[:10] = True
    X, f = kld.adapt(compact, fresh, rng)
    assert X.shape == (100, 3) and f.shape == (100,)
    assert {tuple(x) for x in X} <= {tuple(x) for x in compact}  # a subset, no new poses
    spread = np.column_stack([rng.uniform(0, 30, 1000), rng.uniform(0, 30, 1000),
                              rng.uniform(-np.pi, np.pi, 1000)])
    X, f = kld.adapt(spread, fresh, rng)
    assert len(X) == 3000 and f.sum() >= 10  # every original kept, copies added
    np.testing.assert_array_equal(X[:1000], spread)


def test_bad_settings_name_themselves():
    with pytest.raises(ValueError, match="min_particles"):
        KLDSampling(600, 500)
    with pytest.raises(TypeError, match="min_particles"):
        KLDSampling(2.5, 500)
    with pytest.raises(ValueError, match="kld_epsilon"):
        KLDSampling(100, 500, epsilon=0.0)
    with pytest.raises(ValueError, match="kld_confidence"):
        KLDSampling(100, 500, confidence=1.0)


def test_a_tracking_belief_uses_fewer_particles_and_still_tracks(localizer, features):
    """Started at the true pose, the cloud stays in a few bins: after the first resampling
    the belief runs on ``min_particles``; the fixed-count belief tracks this drive to 0.35 m
    (test_particles.py), and so must this one (measured: 0.14 m)."""
    W, poses, controls = features
    W, poses, controls = W[:121], poses[:121], controls[:120]
    pf = ParticleBelief(localizer, UnicycleModel(0.1), n_particles=1000, min_particles=200,
                        max_injection=0.0, seed=0)
    counts = []
    pf.reset(W[0], x0=poses[0])
    means = [pf.pose_mean]
    for k in range(120):
        pf.step(controls[k], W[k + 1])
        counts.append(len(pf.particles))
        assert len(pf.log_weights) == len(pf.particles)
        means.append(pf.pose_mean)
    # measured: 518 particles on average, 200 while tracking, up to 1000 while the images
    # disagreed with the mode (ambiguous: 10 % drawn from their proposals each step)
    assert min(counts) == 200 and np.mean(counts) < 700, counts
    err = np.hypot(*(np.array(means)[:, :2] - poses[:, :2]).T)
    assert np.sqrt(np.mean(err ** 2)) < 0.35, err.max()


def test_a_start_from_one_image_begins_with_every_particle(localizer, features):
    W, _poses, _ = features
    pf = ParticleBelief(localizer, UnicycleModel(0.1), n_particles=800, min_particles=100,
                        seed=0)
    pf.reset(W[0])
    assert len(pf.particles) == 800


def test_the_default_adapts_from_n_particles_down_to_500(localizer):
    pf = ParticleBelief(localizer, UnicycleModel(0.1))
    assert pf.kld is not None and (pf.kld.min_particles, pf.kld.max_particles) == (500, 2000)
    assert ParticleBelief(localizer, UnicycleModel(0.1), n_particles=300).kld is None
    assert ParticleBelief(localizer, UnicycleModel(0.1), min_particles=None).kld is None
    with pytest.raises(TypeError, match="min_particles"):
        ParticleBelief(localizer, UnicycleModel(0.1), min_particles=2.5)
    with pytest.raises(ValueError, match="min_particles"):
        ParticleBelief(localizer, UnicycleModel(0.1), min_particles=0)
