"""Tests of GrassmannStiefelEigenmaps against manifolds with known geometry.

Magnitudes follow docs/method.md §16.2 (prototype of the polarised alignment).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import orthogonal_procrustes
from sklearn.exceptions import NotFittedError

from localization.gse.embedding import GrassmannStiefelEigenmaps
from localization.synthetic import curved_3manifold, swiss_roll, swiss_roll_tangents


def procrustes_r2(Y: np.ndarray, T: np.ndarray) -> float:
    """R^2 of the best rigid (orthogonal + translation) fit of Y to T."""
    Yc, Tc = Y - Y.mean(0), T - T.mean(0)
    R, _ = orthogonal_procrustes(Yc, Tc)
    return 1.0 - ((Yc @ R - Tc) ** 2).sum() / (Tc ** 2).sum()


def max_angle_deg(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Largest principal angle (degrees) between Span A_i and Span B_i, (n, p, q) each."""
    Qa, _ = np.linalg.qr(A)
    Qb, _ = np.linalg.qr(B)
    s = np.linalg.svd(np.swapaxes(Qa, 1, 2) @ Qb, compute_uv=False)
    return np.degrees(np.arccos(np.clip(s[:, -1], 0.0, 1.0)))


def rel_reconstruction(model: GrassmannStiefelEigenmaps, Z: np.ndarray) -> np.ndarray:
    diam = 2.0 * np.linalg.norm(Z - Z.mean(0), axis=1).max()  # rotation invariant
    return np.linalg.norm(model.inverse_transform(model.transform(Z)) - Z, axis=1) / diam


@pytest.fixture(scope="module")
def roll1000():
    Z, params, iso = swiss_roll(1000, seed=0)
    return Z, params, iso, GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z)


def test_swiss_roll_isometric_embedding_and_health(roll1000):
    Z, _params, iso, g = roll1000
    assert procrustes_r2(g.embedding_, iso) >= 0.999
    # best affine map y -> iso is (nearly) a rotation: singular values ~ 1
    A, *_ = np.linalg.lstsq(np.column_stack([g.embedding_, np.ones(len(Z))]), iso, rcond=None)
    assert np.allclose(np.linalg.svd(A[:2], compute_uv=False), 1.0, atol=0.02)
    # alignment health (method §16.2.2): cond(v_i) ~ 1, frames span the PCA tangents, gap
    assert g.frame_condition_.max() < 1.1
    P = g.frames_ - g.tangents_ @ (np.swapaxes(g.tangents_, 1, 2) @ g.frames_)
    assert np.abs(P).max() < 1e-10
    lam = g.alignment_eigenvalues_
    assert lam[1] < 3 * lam[0] + 1e-12 and lam[2] > 20 * lam[1]
    assert g.n_components_graph_ == 1
    assert g.embedding_.shape == (1000, 2) and g.frames_.shape == (1000, 3, 2)


def test_swiss_roll_tangent_angles(roll1000):
    Z, params, _iso, g = roll1000
    T = swiss_roll_tangents(params)
    ang_pca = max_angle_deg(g.tangents_, T)
    ang_G = max_angle_deg(g.recovery_jacobian(g.transform(Z)), T)
    assert np.median(ang_pca) < 3.0  # method §16.2.1: ~2 deg at n = 1000
    assert np.median(ang_G) < 3.0
    assert np.percentile(ang_G, 95) < 10.0


def test_reconstruction_shrinks_with_n():
    errs = []
    Zt, _, _ = swiss_roll(200, seed=99)
    for n in (500, 1000, 2000):
        Z, _, _ = swiss_roll(n, seed=0)
        g = GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z)
        errs.append((np.median(rel_reconstruction(g, Z)), np.median(rel_reconstruction(g, Zt))))
    ins, oos = np.array(errs).T
    assert ins[1] < 5e-3 and ins[2] < 2.5e-3  # method §16.2.4: ~3e-3 (n=1000), 1.7e-3 (n=2000)
    assert ins[0] > ins[1] > ins[2] and oos[0] > oos[1] > oos[2]
    assert np.all(oos < 3 * ins)  # out-of-sample error of the same order


def test_fit_is_deterministic(roll1000):
    Z, _, _, g = roll1000
    assert np.array_equal(GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z).embedding_,
                          g.embedding_)
    Z3, _ = curved_3manifold(1200, seed=1, ambient_dim=30)  # LOBPCG path (n q > 3000)
    a = GrassmannStiefelEigenmaps(3, n_neighbors=20).fit(Z3)
    b = GrassmannStiefelEigenmaps(3, n_neighbors=20).fit(Z3)
    assert np.array_equal(a.embedding_, b.embedding_)


def test_transform_reproduces_training_embedding_and_is_samplewise(roll1000):
    Z, _, _, g = roll1000
    Y = g.transform(Z)
    assert np.abs(Y - g.embedding_).max() < 1e-3 * np.ptp(g.embedding_)
    rows = [g.transform(Z[i:i + 1])[0] for i in range(0, 40, 7)]
    assert np.allclose(np.array(rows), Y[0:40:7], rtol=0, atol=1e-12)
    Yq = g.embedding_[:30] + 0.1
    assert np.allclose(g.inverse_transform(Yq)[5], g.inverse_transform(Yq[5:6])[0], atol=1e-12)
    assert np.allclose(g.recovery_jacobian(Yq)[5], g.recovery_jacobian(Yq[5:6])[0], atol=1e-12)


def test_rotation_and_shuffle_invariance():
    Z3, params, _iso = swiss_roll(1000, seed=3)
    rng = np.random.default_rng(0)
    E = np.linalg.qr(rng.standard_normal((30, 3)))[0].T  # isometric R^3 -> R^30
    Z = Z3 @ E
    R = np.linalg.qr(rng.standard_normal((30, 30)))[0]
    perm = rng.permutation(len(Z))
    base = GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z)
    rot = GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z @ R)
    shuf = GrassmannStiefelEigenmaps(2, n_neighbors=15).fit(Z[perm])
    e0 = rel_reconstruction(base, Z)
    assert np.allclose(rel_reconstruction(rot, Z @ R), e0, rtol=1e-4, atol=1e-8)
    assert np.allclose(rel_reconstruction(shuf, Z[perm]), e0[perm], rtol=1e-4, atol=1e-8)
    # same embedding up to one global O(q) (and the sample order)
    assert procrustes_r2(rot.embedding_, base.embedding_) > 1 - 1e-8
    assert procrustes_r2(shuf.embedding_, base.embedding_[perm]) > 1 - 1e-8
    # tangents in R^30: angles to the true tangents, rotated along
    T = swiss_roll_tangents(params, E)
    assert np.median(max_angle_deg(base.tangents_, T)) < 3.0
    assert np.allclose(max_angle_deg(rot.tangents_, np.einsum("nDk,DE->nEk", T, R)),
                       max_angle_deg(base.tangents_, T), atol=1e-4)


def _curved_truth(n: int, seed: int, ambient_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """True tangents of curved_3manifold, rebuilding its random map (checked against it)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 1.0, (n, 3))
    A = rng.normal(0.0, 1.0, (6, 3))
    b = rng.uniform(0.0, 2.0 * np.pi, 6)
    E = np.linalg.qr(rng.standard_normal((ambient_dim, 9)))[0].T
    Z = np.column_stack([u, 0.25 * np.sin(np.pi * u @ A.T + b)]) @ E
    J = np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)),
                        0.25 * np.pi * np.cos(np.pi * u @ A.T + b)[:, :, None] * A], axis=1)
    return Z, np.einsum("nkq,kD->nDq", J, E)


def test_curved_3manifold_in_r64():
    """The 3-manifold is curved, so there is no isometric chart to compare with.
    Honest criteria: (1) near-local isometry -- the embedding preserves distances to
    neighbours up to the few per cent of distortion that non-zero curvature forces
    on any flat chart; (2) y is a smooth reparametrisation
    of the true parameters u (high affine R^2, the metric is only mildly non-flat);
    (3) reconstruction and tangent errors are small."""
    n, D = 3000, 64  # (the generator draws its map after u: the manifold depends on n)
    Z, u = curved_3manifold(n, seed=0, ambient_dim=D)
    Zc, T = _curved_truth(n, 0, D)
    assert np.allclose(Z, Zc)
    g = GrassmannStiefelEigenmaps(3, n_neighbors=20).fit(Z)
    Y = g.embedding_
    from sklearn.neighbors import NearestNeighbors
    d, ind = NearestNeighbors(n_neighbors=6).fit(Z).kneighbors(Z)
    ratio = np.linalg.norm(Y[:, None] - Y[ind[:, 1:]], axis=2) / d[:, 1:]
    # a flat chart of a curved manifold must distort a little (measured median 0.965)
    assert 0.93 < np.median(ratio) < 1.02
    A, *_ = np.linalg.lstsq(np.column_stack([Y, np.ones(n)]), u, rcond=None)
    resid = np.column_stack([Y, np.ones(n)]) @ A - u
    assert 1 - (resid ** 2).sum() / ((u - u.mean(0)) ** 2).sum() > 0.99
    assert np.median(rel_reconstruction(g, Z)) < 0.01
    ang_pca = np.median(max_angle_deg(g.tangents_, T))  # measured 4.7 deg (strong curvature)
    ang_G = np.median(max_angle_deg(g.recovery_jacobian(g.transform(Z)), T))  # measured 5.1
    assert ang_pca < 7.0 and ang_G < 7.0 and ang_G < 1.25 * ang_pca
    assert g.frame_condition_.max() < 1.5


def test_out_of_domain_is_flagged(roll1000):
    Z, _, _, g = roll1000
    far = Z[:2] + 1e3
    with pytest.raises(ValueError, match="outside the sample domain"):
        g.transform(far)
    with pytest.raises(ValueError, match="outside the sample domain"):
        g.inverse_transform(g.embedding_[:1] + 1e4)
    g2 = GrassmannStiefelEigenmaps(2, n_neighbors=15, out_of_domain="nan").fit(Z[:500])
    out = g2.transform(np.vstack([Z[:1], far]))
    assert np.isfinite(out[0]).all() and np.isnan(out[1:]).all()


def test_disconnected_sample_raises_with_component_count():
    Z1, _, _ = swiss_roll(300, seed=0)
    Z = np.vstack([Z1, Z1 + 500.0])
    with pytest.raises(ValueError, match="2 connected components.*n_neighbors"):
        GrassmannStiefelEigenmaps(2, n_neighbors=10).fit(Z)


def test_bad_inputs():
    Z, _, _ = swiss_roll(100, seed=0)
    g = GrassmannStiefelEigenmaps(2, n_neighbors=10)
    with pytest.raises(NotFittedError):
        g.transform(Z)
    bad = Z.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        g.fit(bad)
    with pytest.raises(ValueError, match="2-D"):
        g.fit(Z[:, 0])
    with pytest.raises(ValueError, match="n_components"):
        GrassmannStiefelEigenmaps(3, n_neighbors=10).fit(Z)
    with pytest.raises(ValueError, match="more samples than n_neighbors"):
        GrassmannStiefelEigenmaps(2, n_neighbors=10).fit(Z[:8])
    with pytest.raises(ValueError, match="duplicate"):
        g.fit(np.vstack([Z, Z[5:6]]))
    with pytest.warns(RuntimeWarning, match="eigen-gap"):  # 100 points: poorly sampled
        g.fit(Z)
    with pytest.raises(ValueError, match="columns"):
        g.transform(Z[:, :2])
