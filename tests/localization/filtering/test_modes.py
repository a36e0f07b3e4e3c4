"""find_modes against the plain statement of its algorithm (module docstring of _modes)."""

import numpy as np
import pytest

from localization.filtering._modes import cells, find_modes, weighted_pose_stats
from localization.geometry import wrap_angle


def _reference_modes(X, w, radius=1.0, heading_scale=2.0, max_modes=5, min_weight=0.01,
                     max_iter=20):
    """Every iteration over all N particles, the members masked by the weight left."""
    left, modes = w / w.sum(), []
    labels = cells(X, radius, heading_scale)
    while len(modes) < max_modes and left.sum() >= min_weight:
        members = (labels == np.argmax(np.bincount(labels, weights=left))) & (left > 0)
        for _ in range(max_iter):
            mean, _ = weighted_pose_stats(X[members], left[members])
            d = X - mean
            d[:, 2] = heading_scale * wrap_angle(d[:, 2])
            new = (np.sum(d ** 2, axis=1) <= radius ** 2) & (left > 0)
            if not new.any() or np.array_equal(new, members):
                break
            members = new
        mean, cov = weighted_pose_stats(X[members], left[members])
        modes.append((float(left[members].sum()), mean, cov))
        left = np.where(members, 0.0, left)
    return sorted(modes, key=lambda m: -m[0])


@pytest.mark.parametrize("seed", range(5))
def test_find_modes_matches_its_algorithm(seed: int) -> None:
    rng = np.random.default_rng(seed)
    centres = rng.uniform([0, 0, -np.pi], [10, 10, np.pi], (4, 3))
    X = np.vstack([c + rng.normal(0, [0.3, 0.3, 0.2], (150, 3)) for c in centres])
    X = np.vstack([X, rng.uniform([0, 0, -np.pi], [10, 10, np.pi], (100, 3))])
    X[:, 2] = wrap_angle(X[:, 2])
    w = rng.exponential(size=len(X)) * (rng.random(len(X)) > 0.1)  # some zero weights
    got, want = find_modes(X, w), _reference_modes(X, w)
    assert len(got) == len(want)
    for mode, (weight, mean, cov) in zip(got, want, strict=True):
        assert mode.weight == pytest.approx(weight, abs=1e-12)
        np.testing.assert_allclose(mode.mean, mean, atol=1e-9)
        np.testing.assert_allclose(mode.cov, cov, atol=1e-9)
