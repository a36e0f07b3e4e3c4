"""CubeMapCamera on tiny MuJoCo scenes: geometry, colours in the right places, determinism."""

# ruff: noqa: I001  (envs must be imported before mujoco)
from __future__ import annotations

import envs  # noqa: F401  (first: chooses MUJOCO_GL before mujoco is imported)
import mujoco
import numpy as np
import pytest
from scipy import ndimage

from envs import projections as P
from envs.cube_camera import CubeMapCamera, default_face_size

# The robot (a mocap body) faces world +x; its camera "ego" looks along +x with +z up.
# Flat colours: the headlight is pure ambient, no other light.
_HEAD = """<mujoco>
  <visual><headlight ambient="1 1 1" diffuse="0 0 0" specular="0 0 0"/></visual>
  <worldbody>
    <body name="robot" mocap="true" pos="0 0 1">
      <camera name="ego" xyaxes="0 -1 0 0 0 1"/>
    </body>
"""
WALLS = (
    _HEAD
    + """
    <geom type="plane" size="20 20 .1" rgba=".5 .5 .5 1"/>
    <geom type="box" pos=" 4 0 1" size=".1 3 2" rgba="1 0 0 1"/>
    <geom type="box" pos="-4 0 1" size=".1 3 2" rgba="0 1 0 1"/>
    <geom type="box" pos="0  4 1" size="3 .1 2" rgba="0 0 1 1"/>
    <geom type="box" pos="0 -4 1" size="3 .1 2" rgba="1 1 0 1"/>
  </worldbody>
</mujoco>"""
)
RED, GREEN, BLUE, YELLOW = (255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0)

# (azimuth to the left, elevation) in degrees of the markers; several lie on cube seams / corners
MARKERS = [(0, 0), (45, 0), (45, 35.26), (-45, -20), (90, 10), (-100, 30), (125, 0), (120, -20),
           (-125, 15), (20, 50), (-70, -45)]  # fmt: skip
CAM_POS = np.array([0.0, 0.0, 1.0])


def _marker_world(az: float, el: float, dist: float = 4.0) -> np.ndarray:
    a, e = np.radians(az), np.radians(el)
    return CAM_POS + dist * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def _markers_xml() -> str:
    spheres = "".join(
        f'<geom type="sphere" size="0.3" pos="{p[0]} {p[1]} {p[2]}" rgba="1 0 1 1"/>'
        for p in (_marker_world(*m) for m in MARKERS)
    )
    return _HEAD + spheres + "</worldbody></mujoco>"


def _model(xml: str) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def _near(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> np.ndarray:
    return (np.abs(img.astype(int) - np.array(rgb)) <= tol).all(-1)


@pytest.fixture(scope="module")
def walls() -> tuple[mujoco.MjModel, mujoco.MjData]:
    return _model(WALLS)


@pytest.mark.parametrize(
    "projection, kw, project",
    [("fisheye", {"fov": 280.0}, P.fisheye_project),
     ("catadioptric", {"elevation_range": (-60.0, 60.0), "radii": (0.2, 1.0)}, P.catadioptric_project)],
)  # fmt: skip
def test_markers_land_where_the_model_projects_them(projection, kw, project) -> None:
    model, data = _model(_markers_xml())
    size = 128
    with CubeMapCamera(model, size, projection, **kw) as cam:
        img = cam.render(data)
    blobs, n = ndimage.label(_near(img, (255, 0, 255), tol=60), structure=np.ones((3, 3)))
    assert n == len(MARKERS)  # one blob each: nothing doubled or lost at the face seams
    centres = np.array(ndimage.center_of_mass(blobs > 0, blobs, range(1, n + 1)))[:, ::-1] + 0.5
    rot = data.cam_xmat[0].reshape(3, 3)
    for m in MARKERS:
        uv, vis = project(rot.T @ (_marker_world(*m) - data.cam_xpos[0]), size, **kw)
        assert vis
        dist = np.hypot(*(centres - uv).T).min()
        assert dist < 0.75, (m, uv, dist)


def test_fisheye_sees_the_front_hemisphere(walls) -> None:
    model, data = walls
    with CubeMapCamera(model, 64, "fisheye", fov=180.0) as cam:
        img = cam.render(data)
        mask = cam.mask
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    assert not img[~mask].any()
    np.testing.assert_array_equal(img[30:34, 30:34], np.broadcast_to(RED, (4, 4, 3)))  # ahead
    assert _near(img[28:36, 4:10], BLUE).all()  # left (+y world) on the image's left
    assert _near(img[28:36, 54:60], YELLOW).all()  # right
    assert not _near(img, GREEN).any()  # the wall behind is outside a 180-degree view
    assert _near(img[56:60, 30:34], (128, 128, 128), 10).all()  # the floor below


def test_catadioptric_sees_all_around(walls) -> None:
    model, data = walls
    with CubeMapCamera(model, 64, "catadioptric") as cam:
        img = cam.render(data)
        mask = cam.mask
    assert not img[~mask].any()
    r_mid = 32 * (0.3 + 0.7 * 0.5)  # elevation 10 degrees, on the walls
    for az, rgb in ((0, RED), (90, BLUE), (180, GREEN), (-90, YELLOW)):
        a = np.radians(az)
        u, v = 32 - r_mid * np.sin(a), 32 - r_mid * np.cos(a)
        assert _near(img[int(v) - 1 : int(v) + 2, int(u) - 1 : int(u) + 2], rgb).all(), az


def test_camera_follows_the_body_pose(walls) -> None:
    model, _ = walls
    data = mujoco.MjData(model)
    data.mocap_quat[0] = [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]  # yaw +90: face +y
    mujoco.mj_forward(model, data)
    with CubeMapCamera(model, 48, "fisheye") as cam:
        img = cam.render(data)
    assert _near(img[22:26, 22:26], BLUE).all()


def test_renders_are_deterministic_and_fresh(walls) -> None:
    model, data = walls
    with CubeMapCamera(model, 40, "fisheye") as a, CubeMapCamera(model, 40, "fisheye") as b:
        first = a.render(data)
        second = a.render(data)
        np.testing.assert_array_equal(first, second)
        np.testing.assert_array_equal(first, b.render(data))
        assert first is not second


def test_unused_faces_are_skipped_and_face_size_default(walls) -> None:
    model, _ = walls
    with CubeMapCamera(model, 64, "fisheye") as cam:  # 190 degrees: never the back face
        assert cam.faces == (0, 1, 2, 3, 5)
        assert cam.face_size == default_face_size("fisheye", 64) == 39
    with CubeMapCamera(model, (32, 48), "catadioptric", face_size=20, bilinear=False) as cam:
        assert cam.faces == (0, 1, 2, 4, 5)  # elevations >= -20: never the floor face
        assert cam.render(mujoco.MjData(model)).shape == (32, 48, 3)


def test_validation(walls) -> None:
    model, data = walls
    with pytest.raises(ValueError, match="fisheye, catadioptric"):
        CubeMapCamera(model, 32, "pinhole")
    with pytest.raises(ValueError, match="'nose'"):
        CubeMapCamera(model, 32, camera_name="nose")
    for bad in (0, (32,), "32", (32, 0), 2.5):
        with pytest.raises(ValueError, match="size"):
            CubeMapCamera(model, bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="fov"):
        CubeMapCamera(model, 32, "catadioptric", fov=200.0)
    with pytest.raises(ValueError, match="face_size"):
        CubeMapCamera(model, 32, face_size=0)
    with pytest.raises(ValueError, match="render flag"):
        CubeMapCamera(model, 32, render_flags={"mjRND_NOPE": True})
    cam = CubeMapCamera(model, 32)
    cam.close()
    cam.close()  # idempotent
    with pytest.raises(RuntimeError, match="close"):
        cam.render(data)
