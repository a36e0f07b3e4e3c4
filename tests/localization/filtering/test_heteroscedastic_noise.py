"""Heteroscedastic R(theta): the scale model on synthetic data (thin sample -> larger R,
SPD, NaN where undefined, bad settings, state round trip)."""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from localization.filtering.heteroscedastic_noise import (
    HeteroscedasticNoise,
    fit_log_gamma,
    pose_points,
    scaled_covariance,
    squared_scores,
)


def _data(seed: int = 0):
    """Training poses dense for x < 0 (2000) and thin for x > 0 (150); held-out residuals
    three times larger where the sample is thin, and growing with the images' novelty u
    (variance proportional to u)."""
    rng = np.random.default_rng(seed)

    def poses(n, lo, hi):
        return np.column_stack([rng.uniform(lo, hi, n), rng.uniform(0, 2, n),
                                rng.normal(0, 0.1, n)])

    train = np.vstack([poses(2000, -10, 0), poses(150, 0, 10)])
    held = poses(800, -10, 10)
    u = rng.lognormal(0.0, 0.5, 800)
    sd = np.where(held[:, 0] < 0, 0.1, 0.3) * np.sqrt(u)
    e = rng.standard_normal((800, 3)) * sd[:, None]
    J = np.tile(np.eye(3), (800, 1, 1))
    return train, held, e, J, u


def _fitted(**params):
    train, held, e, J, u = _data()
    model = HeteroscedasticNoise(**params)
    index = model.density_index(train)
    geometry = model.geometry(index, held, J, u)
    model.fit(e, held, np.diag([0.02, 0.02, 0.02]), geometry)
    return model, index


def test_scale_grows_where_training_samples_are_thin():
    model, index = _fitted()
    q = np.array([[-5.0, 1.0, 0.0], [-2.0, 1.5, 0.05], [5.0, 1.0, 0.0], [8.0, 0.5, -0.1]])
    s = model.scale(q, model.geometry(index, q, np.tile(np.eye(3), (4, 1, 1))))
    assert np.all(np.isfinite(s))
    assert min(s[2:]) > 3.0 * max(s[:2])  # variance ratio 9 between the halves
    assert model.coef_[1] > 0  # the density term is used, not only the neighbours
    # mean 1 over the held-out poses: only the distribution over the map is learned
    _, held, _, J, u = _data()
    assert np.mean(model.scale(held, model.geometry(index, held, J, u))) == pytest.approx(1.0,
                                                                                       rel=0.1)


def test_an_unfamiliar_image_inflates_the_scale():
    model, index = _fitted()
    q = np.tile([[-5.0, 1.0, 0.0]], (3, 1))
    J = np.tile(np.eye(3), (3, 1, 1))
    s = model.scale(q, model.geometry(index, q, J, np.array([1.0, 4.0, 16.0])))
    assert s[1] > 2.0 * s[0] and s[2] > 2.0 * s[1]  # variance proportional to u
    typical = model.scale(q[:1], model.geometry(index, q[:1], J[:1]))  # no image: u = u_ref
    assert typical[0] == pytest.approx(s[0], rel=0.3)


def test_scale_away_from_every_sample_grows_with_the_distance():
    model, index = _fitted()
    x = np.array([[12.0, 1.0, 0.0], [20.0, 1.0, 0.0], [40.0, 1.0, 0.0]])
    s = model.scale(x, model.geometry(index, x, np.tile(np.eye(3), (3, 1, 1))))
    assert np.all(np.diff(s) >= 0) and s[-1] <= model.max_scale


def test_covariance_is_spd_and_nan_where_undefined():
    model, index = _fitted()
    rng = np.random.default_rng(1)
    q = np.column_stack([rng.uniform(-15, 15, 300), rng.uniform(-3, 5, 300),
                         rng.uniform(-np.pi, np.pi, 300)])
    J = rng.normal(size=(300, 3, 3))
    J[:20] = np.nan  # the maps have no value there
    q[20:25, 2] = np.nan
    s = model.scale(q, model.geometry(index, q, J))
    assert np.all(np.isnan(s[:25])) and np.all(np.isfinite(s[25:]))
    C = np.array([[0.04, 0.01, 0.0], [0.01, 0.02, 0.0], [0.0, 0.0, 1e-4]])
    R = scaled_covariance(C, s)
    assert np.all(np.isnan(R[:25]))
    assert np.allclose(R[25:], np.swapaxes(R[25:], 1, 2))
    assert np.all(np.linalg.eigvalsh(R[25:]) > 0)


def test_state_round_trip():
    model, index = _fitted(n_neighbors=15, min_scale=0.5)
    copy = HeteroscedasticNoise.from_state(model.get_state())
    assert copy.get_params() == model.get_params()
    q = np.array([[-3.0, 1.0, 0.0], [6.0, 1.0, 0.2]])
    J = np.tile(np.eye(3), (2, 1, 1))
    assert np.allclose(copy.scale(q, copy.geometry(index, q, J)),
                       model.scale(q, model.geometry(index, q, J)))
    with pytest.raises(ValueError, match="missing"):
        HeteroscedasticNoise.from_state({"coef": model.coef_})


@pytest.mark.parametrize(("name", "value", "error"), [
    ("n_neighbors", 0, ValueError), ("density_neighbors", 2.5, TypeError),
    ("heading_scale", 0.0, ValueError), ("prior_weight", -1.0, ValueError),
    ("clip_probability", 1.0, ValueError), ("min_scale", 2.0, ValueError),
    ("max_scale", 0.5, ValueError), ("ridge", float("nan"), ValueError)])
def test_bad_settings_name_the_argument(name, value, error):
    _, held, e, _, _ = _data()
    model = HeteroscedasticNoise(**{name: value})
    with pytest.raises(error, match=name):
        model.fit(e, held, np.eye(3), np.ones((len(held), 5)))


def test_bad_inputs_raise_clear_errors():
    train, held, e, J, _ = _data()
    model = HeteroscedasticNoise()
    with pytest.raises(NotFittedError):
        model.scale(held, np.ones((len(held), 5)))
    with pytest.raises(ValueError, match="geometry"):
        model.fit(e, held, np.eye(3), np.ones((len(held), 4)))
    with pytest.raises(ValueError, match="at least"):
        model.fit(e[:10], held[:10], np.eye(3), np.ones((10, 5)))
    with pytest.raises(ValueError, match="novelty"):
        model.geometry(model.density_index(train), held, J, np.ones(3))
    with pytest.raises(ValueError, match="jacobians"):
        model.geometry(model.density_index(train), held, J[:5])
    with pytest.raises(ValueError, match="train_poses"):
        model.density_index(train[:3])
    with pytest.raises(ValueError, match="scale"):
        scaled_covariance(np.eye(3), np.array([1.0, -1.0]))


def test_scores_and_gamma_regression():
    rng = np.random.default_rng(2)
    e = rng.standard_normal((20000, 3)) * [0.1, 0.2, 0.05]
    y = squared_scores(e, np.diag([0.01, 0.04, 0.0025]))
    assert np.mean(y) == pytest.approx(1.0, abs=0.03)
    assert np.isnan(squared_scores(np.full((1, 3), np.nan), np.eye(3))[0])
    x = rng.uniform(-1, 1, (5000, 1))
    t = np.exp(0.5 + 1.5 * x[:, 0]) * rng.gamma(2.0, 0.5, 5000)  # E = exp(0.5 + 1.5 x)
    b = fit_log_gamma(x, t, [(None, None)], ridge=0.0)
    assert b == pytest.approx([0.5, 1.5], abs=0.05)
    assert fit_log_gamma(x, t, [(None, 1.0)], ridge=0.0)[1] == pytest.approx(1.0)
    assert pose_points(np.array([[1.0, 2.0, np.pi / 2]]), 2.0) == pytest.approx(
        np.array([[1.0, 2.0, 0.0, 2.0]]))
