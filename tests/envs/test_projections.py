"""Pure-numpy camera models: cube faces, equidistant fisheye, catadioptric ring, LUT remap."""

from __future__ import annotations

import numpy as np
import pytest

from envs import cube_atlas as A
from envs import projections as P


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


def _centre_offsets(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    v, u = np.mgrid[0:h, 0:w] + 0.5
    return u - w / 2, v - h / 2


# ----------------------------------------------------------------------------- cube faces
def test_face_axes_are_right_handed_opengl_frames() -> None:
    for fwd, right, up in A.FACE_AXES:
        np.testing.assert_allclose(np.cross(fwd, up), right)  # right = forward x up
    np.testing.assert_allclose(np.abs(A.FACE_AXES[:, 0]).sum(0), [2, 2, 2])  # +-x, +-y, +-z


@pytest.mark.parametrize(
    "d, face, a, b",
    [((0, 0, -1), 5, 0, 0), ((1, 0, 0), 0, 0, 0), ((0, 1, 0), 2, 0, 0), ((0, 0, 1), 4, 0, 0),
     ((0.5, 0.25, -1), 5, 0.5, 0.25), ((-1, 0.5, 0.2), 1, -0.2, 0.5)],
)  # fmt: skip
def test_cube_face_lookup_known_directions(d, face, a, b) -> None:
    k, fa, fb = A.cube_face_lookup(np.array(d, float))
    assert int(k) == face and fa == pytest.approx(a) and fb == pytest.approx(b)


@pytest.mark.parametrize("pad", [0, 1, 2])
def test_cube_face_pixel_centres_round_trip(pad: int) -> None:
    f = 7
    dirs = A.cube_face_directions(f, pad)
    assert dirs.shape == (6, f + 2 * pad, f + 2 * pad, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0)
    inner = dirs[:, pad : pad + f, pad : pad + f]  # padded pixels belong to neighbouring faces
    face, row, col = A.cube_face_pixel(inner, f, pad)
    k, i, j = np.meshgrid(np.arange(6), np.arange(f) + pad, np.arange(f) + pad, indexing="ij")
    np.testing.assert_array_equal(face, k)
    np.testing.assert_allclose(row, i, atol=1e-9)
    np.testing.assert_allclose(col, j, atol=1e-9)


def test_atlas_places_faces_on_the_grid() -> None:
    f, pad = 5, 1
    g = f + 2 * pad
    atlas = A.atlas_directions(f, pad, grid=(2, 3))
    faces = A.cube_face_directions(f, pad)
    assert atlas.shape == (2 * g, 3 * g, 3)
    np.testing.assert_array_equal(atlas[g : 2 * g, 2 * g :], faces[5])  # face 5: row 1, col 2


# ----------------------------------------------------------------------------- fisheye
def test_fisheye_axis_and_90_degrees() -> None:
    size, fov = 64, 190.0
    f = P.fisheye_focal(size, fov)
    assert f == pytest.approx(32 / np.radians(95))
    dirs = np.array([[0, 0, -1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    uv, vis = P.fisheye_project(dirs, size, fov)
    r90 = f * np.pi / 2
    np.testing.assert_allclose(
        uv, [[32, 32], [32 + r90, 32], [32, 32 - r90], [32 - r90, 32], [32, 32 + r90]]
    )
    assert vis.all()
    _, vis_back = P.fisheye_project(np.array([0.0, 0.0, 1.0]), size, fov)
    assert not vis_back
    # with a 180-degree lens, 90 degrees off axis is exactly the image circle
    uv180, _ = P.fisheye_project(np.array([1.0, 0, 0]), size, 180.0)
    assert uv180[0] - 32 == pytest.approx(32)


@pytest.mark.parametrize("size", [(48, 48), (40, 56)])
def test_fisheye_round_trip_and_disc_mask(size: tuple[int, int]) -> None:
    h, w = size
    dirs, valid = P.fisheye_directions(size, 200.0)
    assert dirs.shape == (h, w, 3) and valid.shape == (h, w)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0)
    x, y = _centre_offsets(h, w)
    np.testing.assert_array_equal(valid, np.hypot(x, y) <= min(h, w) / 2)
    uv, vis = P.fisheye_project(dirs[valid], size, 200.0)
    v, u = np.nonzero(valid)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], -1), atol=1e-9)
    assert vis.all()
    # the angle from the axis grows linearly with the radius: r = f * angle
    angle = np.radians(_angle_deg(dirs, np.array([0.0, 0, -1])))
    np.testing.assert_allclose(angle[valid], np.hypot(x, y)[valid] / P.fisheye_focal(size, 200.0))


# ----------------------------------------------------------------------------- catadioptric
def _az_el(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.array([-np.sin(az) * np.cos(el), np.sin(el), -np.cos(az) * np.cos(el)])


def test_catadioptric_documented_ring_positions() -> None:
    size, er, radii = 100, (-20.0, 40.0), (0.3, 1.0)
    r_in, r_out, r0 = 15.0, 50.0, 15.0 + 35.0 / 3  # elevation 0 is 1/3 of the way out
    cases = {  # (azimuth, elevation) -> (u, v): forward up, left left, behind down
        (0, 0): (50, 50 - r0), (90, 0): (50 - r0, 50), (180, 0): (50, 50 + r0),
        (-90, 0): (50 + r0, 50), (0, -20): (50, 50 - r_in), (0, 40): (50, 50 - r_out),
        (90, 40): (50 - r_out, 50), (180, -20): (50, 50 + r_in),
    }  # fmt: skip
    dirs = np.array([_az_el(*k) for k in cases])
    uv, vis = P.catadioptric_project(dirs, size, er, radii)
    np.testing.assert_allclose(uv, np.array(list(cases.values()), float), atol=1e-9)
    assert vis.all()
    _, vis_out = P.catadioptric_project(np.array([_az_el(0, 60), _az_el(30, -30)]), size, er, radii)
    assert not vis_out.any()


def test_catadioptric_round_trip_and_annulus_mask() -> None:
    size, er, radii = (60, 60), (-30.0, 50.0), (0.25, 0.9)
    dirs, valid = P.catadioptric_directions(size, er, radii)
    x, y = _centre_offsets(60, 60)
    r = np.hypot(x, y)
    np.testing.assert_array_equal(valid, (r >= 0.25 * 30) & (r <= 0.9 * 30))
    uv, vis = P.catadioptric_project(dirs[valid], size, er, radii)
    v, u = np.nonzero(valid)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], -1), atol=1e-9)
    assert vis.all()
    el = np.degrees(np.arcsin(dirs[valid][:, 1]))
    assert el.min() >= er[0] - 1e-9 and el.max() <= er[1] + 1e-9


# ----------------------------------------------------------------------------- LUT + remap
def _colour_atlas(face_size: int, pad: int = 1) -> np.ndarray:
    """A cube atlas whose colour encodes the direction: rgb = 127.5 (1 + d)."""
    return np.rint(127.5 * (1.0 + A.atlas_directions(face_size, pad))).astype(np.uint8)


def _decode(img: np.ndarray) -> np.ndarray:
    return img.astype(float) / 127.5 - 1.0


@pytest.mark.parametrize(
    "projection, kw, face_size",
    [("fisheye", {"fov": 190.0}, 39), ("fisheye", {"fov": 270.0}, 32), ("catadioptric", {}, 64)],
)
def test_remap_is_continuous_across_seams_and_decodes_directions(projection, kw, face_size) -> None:
    dirs, valid = P.projection_directions(projection, 64, **kw)
    lut = A.build_lut(dirs, face_size, valid)
    img = A.remap(_colour_atlas(face_size), lut)
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    assert not img[~valid].any()  # black outside the disc / annulus
    # the colour decodes back to the pixel's own direction
    err = _angle_deg(_decode(img)[valid], dirs[valid])
    assert err.max() < 1.5, err.max()
    # no jumps: neighbouring colours differ no more than their directions do (+ rounding)
    col = img.astype(float)
    nxt = np.roll(np.arange(64), -1)  # next row / column (wraps at the border: excluded)
    for axis in (0, 1):

        def take(a: np.ndarray, axis: int = axis) -> np.ndarray:
            return np.take(a, nxt, axis=axis)

        ok = valid & take(valid)
        ok[(slice(None),) * axis + (-1,)] = False
        dcol = np.abs(col - take(col)).max(-1)
        ddir = 127.5 * np.abs(dirs - take(dirs)).max(-1)
        assert (dcol[ok] <= ddir[ok] + 3.0).all(), (dcol[ok] - ddir[ok]).max()


def test_nearest_lut_samples_the_containing_face_pixel() -> None:
    f = 16
    dirs, valid = P.fisheye_directions(48, 190.0)
    lut = A.build_lut(dirs, f, valid, pad=0, bilinear=False)
    assert lut.index.shape == (1, 48, 48) and lut.buffer_shape == (2 * f, 3 * f, 3)
    img = A.remap(_colour_atlas(f, pad=0), lut)
    assert not img[~valid].any()
    # within half a face-pixel diagonal: atan(sqrt(2) / F) at most
    err = _angle_deg(_decode(img)[valid], dirs[valid])
    assert err.max() < np.degrees(np.arctan(np.sqrt(2) / f)) + 0.5


def test_bilinear_weights_sum_to_one_inside_mask() -> None:
    dirs, valid = P.catadioptric_directions(32)
    lut = A.build_lut(dirs, 20, valid)
    s = lut.weight[..., 0].sum(0)
    np.testing.assert_allclose(s[valid], 1.0, atol=1e-6)
    np.testing.assert_array_equal(s[~valid], 0.0)
    assert (lut.index >= 0).all() and (lut.index < np.prod(lut.buffer_shape[:2])).all()


def test_validation_errors() -> None:
    with pytest.raises(ValueError, match="fisheye, catadioptric"):
        P.projection_directions("pinhole", 32)
    for bad in (0, 1, (32,), "32", 3.5, True, (32, -1)):
        with pytest.raises(ValueError, match="size"):
            P.fisheye_directions(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fov"):
        P.fisheye_directions(32, 360.0)
    with pytest.raises(ValueError, match="elevation_range"):
        P.catadioptric_directions(32, (40.0, -20.0))
    with pytest.raises(ValueError, match="radii"):
        P.catadioptric_directions(32, radii=(0.5, 0.2))
    dirs, valid = P.fisheye_directions(16)
    with pytest.raises(ValueError, match="pad"):
        A.build_lut(dirs, 8, valid, pad=0)
    with pytest.raises(ValueError, match="shape"):
        A.build_lut(dirs[0], 8)
    lut = A.build_lut(dirs, 8, valid)
    with pytest.raises(ValueError, match="cube buffer"):
        A.remap(np.zeros((10, 30, 3), np.uint8), lut)
    with pytest.raises(ValueError, match="NaN"):
        P.fisheye_project(np.array([np.nan, 0, -1]), 16)
