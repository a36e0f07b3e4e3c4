"""The cube map of the omnidirectional cameras: six 90-degree perspective faces in one
atlas buffer, and the lookup table that resamples them into a fisheye or catadioptric image
(:func:`build_lut`, :func:`remap`). Pure numpy; the projections themselves are in
:mod:`envs.projections`, whose conventions (camera frame, pixel centres) hold here.

Cube map: face ``k`` looks along ``FACE_AXES[k, 0]`` (its forward axis) with
image right ``FACE_AXES[k, 1]`` and image up ``FACE_AXES[k, 2]``; the face
order is ``+x, -x, +y, -y, +z, -z`` (right, left, up, down, back, front). A
direction ``d`` on face ``k`` has the face coordinates (tangent-plane)
``a = <d, right> / <d, forward>``, ``b = <d, up> / <d, forward>`` in
``[-1, 1]``. A face has ``F x F`` pixels covering ``[-1, 1]^2``, plus ``pad``
extra pixels on every side (rendered with the same focal length, so the padded
face is ``G = F + 2 pad`` pixels wide) so that bilinear interpolation never
has to cross a face seam. The six faces are stored in one atlas buffer of
shape ``(rows * G, cols * G, 3)``, face ``k`` in grid cell
``(k // cols, k % cols)``; the default grid is ``(2, 3)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FACE_NAMES: tuple[str, ...] = ("right", "left", "up", "down", "back", "front")
#: (6, 3, 3): per face the rows forward, image-right, image-up (camera frame);
#: right = forward x up, as for an OpenGL camera.


FACE_AXES: NDArray[np.float64] = np.array(
    [
        [[1, 0, 0], [0, 0, 1], [0, 1, 0]],  # +x right
        [[-1, 0, 0], [0, 0, -1], [0, 1, 0]],  # -x left
        [[0, 1, 0], [1, 0, 0], [0, 0, 1]],  # +y up
        [[0, -1, 0], [1, 0, 0], [0, 0, -1]],  # -y down
        [[0, 0, 1], [-1, 0, 0], [0, 1, 0]],  # +z back
        [[0, 0, -1], [1, 0, 0], [0, 1, 0]],  # -z front (optical axis)
    ],
    dtype=np.float64,
)


DEFAULT_GRID: tuple[int, int] = (2, 3)


def image_shape(size: int | tuple[int, int]) -> tuple[int, int]:
    """Return ``(H, W)`` from an int (square) or an ``(H, W)`` pair; ValueError if invalid."""
    if isinstance(size, (int, np.integer)) and not isinstance(size, bool):
        hw = (int(size), int(size))
    elif (
        isinstance(size, (tuple, list))
        and len(size) == 2
        and all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in size)
    ):
        hw = (int(size[0]), int(size[1]))
    else:
        raise ValueError(f"image size must be an int or an (H, W) pair of ints, got {size!r}")
    if min(hw) < 2:
        raise ValueError(f"image size must be at least 2 x 2 pixels, got {hw}")
    return hw


def _unit(directions: ArrayLike) -> NDArray[np.float64]:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim < 1 or d.shape[-1] != 3:
        raise ValueError(f"directions must have shape (..., 3), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("directions contain NaN or inf")
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise ValueError("directions contain a zero vector")
    return d / n


def _pixel_centres(hw: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Offsets ``(x, y)`` of the pixel centres from the image centre, x right, y up, (H, W) each."""
    h, w = hw
    v, u = np.mgrid[0:h, 0:w] + 0.5
    return u - w / 2.0, h / 2.0 - v


# ----------------------------------------------------------------------------- cube faces


def cube_face_lookup(
    directions: ArrayLike,
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Find the cube face each direction lands on and its face coordinates.

    The face is the one whose forward axis has the largest dot product with ``d``
    (the dominant component with its sign); then ``a = <d, right> / <d, forward>``
    and ``b = <d, up> / <d, forward>``, both in ``[-1, 1]``. ``directions`` has
    shape (..., 3), camera frame, any non-zero length.

    Returns
    -------
    face : ndarray of intp, shape (...)
        Face index into :data:`FACE_AXES`.
    a, b : ndarray of float64, shape (...)
        Face coordinates (right, up).
    """
    d = _unit(directions)
    proj = d @ FACE_AXES[:, 0].T  # (..., 6) dot with every forward axis
    face = np.argmax(proj, axis=-1)
    axes = FACE_AXES[face]  # (..., 3, 3)
    fwd = np.einsum("...i,...i->...", d, axes[..., 0, :])
    a = np.einsum("...i,...i->...", d, axes[..., 1, :]) / fwd
    b = np.einsum("...i,...i->...", d, axes[..., 2, :]) / fwd
    return face, np.clip(a, -1.0, 1.0), np.clip(b, -1.0, 1.0)


def cube_face_pixel(
    directions: ArrayLike, face_size: int, pad: int = 0
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Continuous pixel position of directions on the (padded) cube faces.

    ``col = (a + 1) / 2 * F + pad - 1/2`` and ``row = (1 - b) / 2 * F + pad - 1/2``,
    in units where pixel ``(i, j)`` of the padded ``G x G`` face has its centre at
    ``(row, col) = (i, j)``. ``directions`` has shape (..., 3); ``face_size`` is ``F``
    and ``pad`` the extra pixels per side. Returns ``face`` (intp), ``row`` and ``col``
    (float64), each of shape (...).
    """
    face, a, b = cube_face_lookup(directions)
    f = float(face_size)
    return face, (1.0 - b) / 2.0 * f + pad - 0.5, (a + 1.0) / 2.0 * f + pad - 0.5


def cube_face_directions(face_size: int, pad: int = 0) -> NDArray[np.float64]:
    """Unit directions through the pixel centres of the six (padded) cube faces.

    Pixel ``(i, j)`` of face ``k`` has ``a = (2 (j - pad) + 1) / F - 1`` and
    ``b = 1 - (2 (i - pad) + 1) / F`` and direction
    ``normalize(forward_k + a right_k + b up_k)``; the inverse of :func:`cube_face_pixel`.

    Returns
    -------
    ndarray of float64, shape (6, G, G, 3) with ``G = face_size + 2 pad``.
    """
    f, g = float(face_size), face_size + 2 * pad
    idx = np.arange(g, dtype=np.float64)
    a = (2.0 * (idx - pad) + 1.0) / f - 1.0
    b = 1.0 - (2.0 * (idx - pad) + 1.0) / f
    bb, aa = np.meshgrid(b, a, indexing="ij")  # (G, G): row -> b, col -> a
    d = (
        FACE_AXES[:, None, None, 0, :]
        + aa[None, :, :, None] * FACE_AXES[:, None, None, 1, :]
        + bb[None, :, :, None] * FACE_AXES[:, None, None, 2, :]
    )
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def atlas_directions(
    face_size: int, pad: int = 0, grid: tuple[int, int] = DEFAULT_GRID
) -> NDArray[np.float64]:
    """Directions of every pixel of the cube atlas buffer, shape (rows G, cols G, 3)."""
    rows, cols = grid
    if rows * cols < 6:
        raise ValueError(f"cube atlas grid {grid} has fewer than 6 cells")
    g = face_size + 2 * pad
    out = np.zeros((rows * g, cols * g, 3))
    for k, d in enumerate(cube_face_directions(face_size, pad)):
        r, c = divmod(k, cols)
        out[r * g : (r + 1) * g, c * g : (c + 1) * g] = d
    return out


# ----------------------------------------------------------------------------- fisheye


@dataclass(frozen=True)
class CubeLUT:
    """Precomputed gather from a cube atlas buffer to an output image.

    Attributes
    ----------
    index : ndarray of intp, shape (K, H, W)
        Flat pixel indices into ``buffer.reshape(-1, 3)`` (K = 4 bilinear, 1 nearest).
    weight : ndarray of float32, shape (K, H, W, 1)
        Interpolation weights, summing to 1 inside the mask and 0 outside.
    mask : ndarray of bool, shape (H, W)
    face_size, pad : int
    grid : (int, int)
    """

    index: NDArray[np.intp]
    weight: NDArray[np.float32]
    mask: NDArray[np.bool_]
    face_size: int
    pad: int
    grid: tuple[int, int]

    @property
    def buffer_shape(self) -> tuple[int, int, int]:
        """Shape ``(rows G, cols G, 3)`` of the cube atlas the table indexes."""
        g = self.face_size + 2 * self.pad
        return (self.grid[0] * g, self.grid[1] * g, 3)


def build_lut(
    directions: ArrayLike,
    face_size: int,
    valid: ArrayLike | None = None,
    *,
    pad: int = 1,
    bilinear: bool = True,
    grid: tuple[int, int] = DEFAULT_GRID,
) -> CubeLUT:
    """Precompute where each output pixel samples the cube atlas.

    With ``(face, row, col)`` from :func:`cube_face_pixel`, the atlas pixel of face
    pixel ``(i, j)`` is ``(r_k G + i, c_k G + j)`` with ``(r_k, c_k) = divmod(k, cols)``.
    Bilinear: the 4 pixels around ``(row, col)`` with weights ``(1-fy)(1-fx)``,
    ``(1-fy) fx``, ``fy (1-fx)``, ``fy fx`` (needs ``pad >= 1`` so the neighbours
    stay on the face); nearest: the pixel containing the point.

    Parameters
    ----------
    directions : array_like, shape (H, W, 3)
        Camera-frame direction of every output pixel.
    face_size : int
        ``F``, pixels across the 90-degree face.
    valid : array_like of bool, shape (H, W), optional
        Output pixels to fill; the others get weight 0 (black).
    pad : int
        Padding pixels per face side (>= 1 for bilinear).
    bilinear : bool
        Bilinear (K = 4) or nearest-neighbour (K = 1) sampling.
    grid : (int, int)
        Atlas layout ``(rows, cols)``, ``rows * cols >= 6``.

    Returns
    -------
    CubeLUT
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 3 or d.shape[-1] != 3:
        raise ValueError(f"directions must have shape (H, W, 3), got {d.shape}")
    if not (isinstance(face_size, (int, np.integer)) and face_size >= 1):
        raise ValueError(f"face_size must be a positive int, got {face_size!r}")
    if pad < (1 if bilinear else 0):
        raise ValueError(f"bilinear sampling needs pad >= 1, got pad={pad}")
    rows, cols = grid
    if rows * cols < 6:
        raise ValueError(f"cube atlas grid {grid} has fewer than 6 cells")
    mask = np.ones(d.shape[:2], bool) if valid is None else np.asarray(valid, dtype=bool)
    if mask.shape != d.shape[:2]:
        raise ValueError(f"valid must have shape {d.shape[:2]}, got {mask.shape}")
    g = face_size + 2 * pad
    face, row, col = cube_face_pixel(d, face_size, pad)
    base_r, base_c = (face // cols) * g, (face % cols) * g
    width = cols * g
    if bilinear:
        r0 = np.clip(np.floor(row), 0, g - 2).astype(np.intp)
        c0 = np.clip(np.floor(col), 0, g - 2).astype(np.intp)
        fy, fx = row - r0, col - c0
        idx = np.stack(
            [(base_r + r0 + dr) * width + base_c + c0 + dc for dr in (0, 1) for dc in (0, 1)],
        )
        wgt = np.stack([(1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx), fy * fx])
    else:
        r0 = np.clip(np.floor(row + 0.5), 0, g - 1).astype(np.intp)
        c0 = np.clip(np.floor(col + 0.5), 0, g - 1).astype(np.intp)
        idx = ((base_r + r0) * width + base_c + c0)[None]
        wgt = np.ones(idx.shape)
    wgt = np.ascontiguousarray((wgt * mask)[..., None], dtype=np.float32)
    idx = np.ascontiguousarray(idx, dtype=np.intp)
    return CubeLUT(idx, wgt, mask, int(face_size), int(pad), (rows, cols))


def remap(cube_buffer: NDArray[np.uint8], lut: CubeLUT) -> NDArray[np.uint8]:
    """Resample a cube atlas into the output image: one gather plus a weighted sum.

    ``out[h, w] = sum_k weight[k, h, w] * buffer_flat[index[k, h, w]]``.

    Parameters
    ----------
    cube_buffer : ndarray of uint8, shape ``lut.buffer_shape`` (rows G, cols G, 3)
    lut : CubeLUT

    Returns
    -------
    ndarray of uint8, shape (H, W, 3); black outside ``lut.mask``.
    """
    if cube_buffer.shape != lut.buffer_shape:
        raise ValueError(f"cube buffer must have shape {lut.buffer_shape}, got {cube_buffer.shape}")
    # np.take is several times faster than fancy indexing for this gather
    samples = np.take(cube_buffer.reshape(-1, 3), lut.index, axis=0)  # (K, H, W, 3)
    if len(samples) == 1:
        return samples[0] * lut.mask[..., None].astype(np.uint8)
    acc = samples[0] * lut.weight[0]
    for k in range(1, len(samples)):
        acc += samples[k] * lut.weight[k]
    return (acc + 0.5).astype(np.uint8)
