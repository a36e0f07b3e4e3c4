"""Synthetic manifolds with known parameters, for tests and benchmarks.

Every generator takes ``n`` and a ``seed`` and returns float64 arrays: the
ambient points and the true intrinsic coordinates (and, where the manifold is
intrinsically flat, coordinates that are isometric to it).
"""

from __future__ import annotations

import numpy as np

from localization.geometry import Array


def _orthonormal_embedding(rng: np.random.Generator, d: int, D: int) -> Array:
    """A random (d, D) matrix with orthonormal rows: an isometric map R^d -> R^D."""
    Q, _ = np.linalg.qr(rng.standard_normal((D, d)))
    return Q.T


def swiss_roll(n: int, seed: int = 0, ambient_dim: int = 3) -> tuple[Array, Array, Array]:
    """Swiss roll ``(t cos t, h, t sin t)``, t in [1.5 pi, 4.5 pi], h in [0, 20].

    Returns
    -------
    Z : ndarray of shape (n, ambient_dim)
        Points (isometrically embedded in R^ambient_dim when ambient_dim > 3).
    params : ndarray of shape (n, 2)
        The parameters (t, h).
    iso : ndarray of shape (n, 2)
        Isometric coordinates (arc length, h).
    """
    rng = np.random.default_rng(seed)
    t = rng.uniform(1.5 * np.pi, 4.5 * np.pi, n)
    h = rng.uniform(0.0, 20.0, n)
    Z = np.column_stack([t * np.cos(t), h, t * np.sin(t)])
    # arc length of the spiral r = t: s(t) = (t sqrt(1+t^2) + asinh t) / 2
    s = 0.5 * (t * np.sqrt(1.0 + t**2) + np.arcsinh(t))
    if ambient_dim > 3:
        Z = Z @ _orthonormal_embedding(rng, 3, ambient_dim)
    return Z, np.column_stack([t, h]), np.column_stack([s - s.min(), h])


def swiss_roll_tangents(params: Array, ambient_basis: Array | None = None) -> Array:
    """True orthonormal tangent bases of :func:`swiss_roll` at ``params`` (n, 2) -> (n, D, 2)."""
    t = params[:, 0]
    dt = np.column_stack([np.cos(t) - t * np.sin(t), np.zeros_like(t), np.sin(t) + t * np.cos(t)])
    dt /= np.linalg.norm(dt, axis=1, keepdims=True)
    dh = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    T = np.stack([dt, dh], axis=2)
    if ambient_basis is not None:
        T = np.einsum("nik,iD->nDk", T, ambient_basis)
    return T


def helix(n: int, seed: int = 0, turns: float = 3.0, noise: float = 0.0) -> tuple[Array, Array]:
    """A helix in R^3 (intrinsic dimension 1); returns points (n, 3) and the angle (n, 1)."""
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.0, 2.0 * np.pi * turns, n)
    Z = np.column_stack([np.cos(s), np.sin(s), 0.2 * s])
    return Z + noise * rng.standard_normal(Z.shape), s[:, None]


def curved_3manifold(n: int, seed: int = 0, ambient_dim: int = 30) -> tuple[Array, Array]:
    """A smooth curved 3-manifold in R^ambient_dim (intrinsic dimension 3).

    The graph of smooth functions of u in [0, 1]^3, embedded by a random
    orthonormal map: ``Z = [u, sin(pi a_k . u + b_k) / 4] @ E``.
    """
    rng = np.random.default_rng(seed)
    u = rng.uniform(0.0, 1.0, (n, 3))
    k = 6
    A = rng.normal(0.0, 1.0, (k, 3))
    b = rng.uniform(0.0, 2.0 * np.pi, k)
    graph = np.column_stack([u, 0.25 * np.sin(np.pi * u @ A.T + b)])
    return graph @ _orthonormal_embedding(rng, 3 + k, ambient_dim), u


class FeatureMap:
    """A smooth synthetic feature-modelling function Phi: theta -> w in R^m.

    ``Phi_k(theta) = sin(pi a_k . e(theta) + b_k)`` with ``a_k ~ N(0, scale^2)``
    (docs/method.md §16.2.8) where ``e(theta)`` is theta itself, except
    that each periodic column phi becomes (cos phi, sin phi) / (2 pi) * period_scale.
    """

    def __init__(self, dim_theta: int, m: int = 30, seed: int = 0, scale: float = 1.5,
                 periodic: tuple[int, ...] = (), period_scale: float = 1.0) -> None:
        rng = np.random.default_rng(seed)
        self.dim_theta, self.m, self.periodic = dim_theta, m, tuple(periodic)
        self.period_scale = period_scale
        d_e = dim_theta + len(self.periodic)
        self.A = rng.normal(0.0, scale, (m, d_e))
        self.b = rng.uniform(0.0, 2.0 * np.pi, m)

    def _lift(self, theta: Array) -> tuple[Array, Array]:
        """e(theta) (n, d_e) and de/dtheta (n, d_e, d)."""
        n, d = theta.shape
        cols, jac = [], []
        for j in range(d):
            e_j = np.zeros((n, d))
            if j in self.periodic:
                c = self.period_scale / (2.0 * np.pi)
                cols += [c * np.cos(theta[:, j]), c * np.sin(theta[:, j])]
                j1, j2 = e_j.copy(), e_j.copy()
                j1[:, j], j2[:, j] = -c * np.sin(theta[:, j]), c * np.cos(theta[:, j])
                jac += [j1, j2]
            else:
                cols.append(theta[:, j])
                e_j[:, j] = 1.0
                jac.append(e_j)
        return np.column_stack(cols), np.stack(jac, axis=1)

    def __call__(self, theta: Array) -> Array:
        e, _ = self._lift(np.atleast_2d(theta))
        return np.sin(np.pi * e @ self.A.T + self.b)

    def jacobian(self, theta: Array) -> Array:
        """dPhi/dtheta, shape (n, m, dim_theta)."""
        e, de = self._lift(np.atleast_2d(theta))
        c = np.cos(np.pi * e @ self.A.T + self.b)
        return np.pi * np.einsum("nm,me,ned->nmd", c, self.A, de)


def regression_manifold(n: int, dim_theta: int = 2, m: int = 30, seed: int = 0,
                        map_seed: int = 1234) -> tuple[Array, Array, FeatureMap]:
    """Samples (w = Phi(theta), theta) of a synthetic regression manifold.

    ``dim_theta=2``: theta uniform in [0, 1]^2 (docs/method.md §16.2.8).
    ``dim_theta=3``: theta = (x, y, yaw), (x, y) in [0, 1]^2 and yaw uniform in
    (-pi, pi], a periodic column (index 2) like a robot pose.

    Returns
    -------
    W : ndarray of shape (n, m)
    Theta : ndarray of shape (n, dim_theta)
    phi : FeatureMap
        The true Phi, with ``phi.jacobian``; the same ``map_seed`` gives the same
        Phi, so train and test sets can use different ``seed``.
    """
    if dim_theta not in (2, 3):
        raise ValueError(f"dim_theta must be 2 or 3, got {dim_theta}")
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0.0, 1.0, (n, dim_theta))
    periodic: tuple[int, ...] = ()
    if dim_theta == 3:
        theta[:, 2] = rng.uniform(-np.pi, np.pi, n)
        periodic = (2,)
    phi = FeatureMap(dim_theta, m=m, seed=map_seed, periodic=periodic)
    return phi(theta), theta, phi


def route_curve(s: Array) -> Array:
    """A closed smooth route in [0, 1]^2: positions (n, 2) at loop parameter s (one lap
    per unit of s)."""
    t = 2.0 * np.pi * np.asarray(s, dtype=np.float64)
    return np.column_stack([0.5 + 0.4 * np.cos(t), 0.5 + 0.3 * np.sin(t) + 0.1 * np.sin(2 * t)])


def route_manifold(n: int, m: int = 30, seed: int = 0, laps: float = 1.5,
                   lateral: float = 0.003, map_seed: int = 1234
                   ) -> tuple[Array, Array, Array, FeatureMap]:
    """Samples along a closed route driven ``laps`` times, like the paper's vehicle data.

    Positions theta (n, 2) at a uniform random loop parameter ``s`` in [0, laps),
    plus Gaussian lateral noise (sd ``lateral``), features ``w = Phi(theta)`` of the
    same :class:`FeatureMap` as :func:`regression_manifold` (dim_theta=2). The
    sample is a closed 1-D curve: intrinsic dimension 1, one loop.

    Returns
    -------
    W : ndarray of shape (n, m)
    Theta : ndarray of shape (n, 2)
    s : ndarray of shape (n,)
        Loop parameter (fractional part = position along the loop).
    phi : FeatureMap
    """
    rng = np.random.default_rng(seed)
    s = np.sort(rng.uniform(0.0, laps, n))
    theta = route_curve(s) + rng.normal(0.0, lateral, (n, 2))
    phi = FeatureMap(2, m=m, seed=map_seed)
    return phi(theta), theta, s, phi
