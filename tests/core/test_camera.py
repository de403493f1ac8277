"""The pinhole + distortion model against OpenCV and against exact geometry."""

import json

import cv2
import numpy as np
import pytest

from rangekit.camera import PinholeCamera, pixel_rays
from rangekit.errors import ConfigError
from rangekit.geometry import look_at, transform_vectors
from rangekit.sim import default_rig

DIST_MODELS = {
    "5": [-0.08, 0.12, 2e-4, -1e-4, 0.01],
    "8 rational": [0.1, -0.05, 1e-3, -5e-4, 0.02, 0.15, -0.03, 0.01],
    "12 thin prism": [-0.1, 0.05, 1e-3, 2e-4, -0.01, 0.02, 0.01, 0.0, 1e-3, -5e-4, 2e-4, 1e-4],
}


def make_cam(dist, size=(1280, 1024)):
    K = np.array([[1800.0, 0.0, 645.3], [0, 1805.0, 508.7], [0, 0, 1]])
    return PinholeCamera(K, *size, dist=np.array(dist, float), T_world_cam=look_at([0.1, -0.5, 0.2], [0, 0, 0.05]))


@pytest.mark.parametrize("name", DIST_MODELS)
def test_project_matches_opencv(name):
    cam = make_cam(DIST_MODELS[name])
    P = np.random.default_rng(0).uniform(-0.1, 0.1, (2000, 3))
    T = cam.T_cam_world
    rvec, _ = cv2.Rodrigues(T[:3, :3])
    ref, _ = cv2.projectPoints(P, rvec, T[:3, 3], cam.K, cam.dist)
    assert np.abs(cam.project(P) - ref[:, 0]).max() < 1e-9


@pytest.mark.parametrize("name", DIST_MODELS)
def test_rays_round_trip_every_pixel(name):
    cam = make_cam(DIST_MODELS[name])
    uv = cam.pixel_grid()
    o, d = cam.rays(uv)
    assert np.abs(np.linalg.norm(d, axis=1) - 1).max() < 1e-12
    assert np.abs(o - cam.center).max() == 0
    for depth in (0.3, 2.0):
        err = np.abs(cam.project(o + depth * d) - uv).max()
        assert err <= 1e-6, f"round trip error {err} px"


def test_default_rig_devices_round_trip():
    rig = default_rig()
    for dev in (rig.camera, rig.projector):
        uv = dev.pixel_grid()
        o, d = dev.rays(uv)
        assert np.abs(dev.project(o + 0.5 * d) - uv).max() <= 1e-6


@pytest.mark.parametrize("name", DIST_MODELS)
def test_pixel_rays_are_camera_rays_bit_for_bit(name):
    """The one per-pixel ray builder: camera frame, (H, W, 3), cached; in world, exactly camera.rays."""
    cam = make_cam(DIST_MODELS[name], size=(320, 256))
    d = pixel_rays(cam)
    assert d.shape == (256, 320, 3) and d.dtype == np.float64 and not d.flags.writeable
    assert pixel_rays(cam.with_pose(np.eye(4))) is d  # depends on the lens only
    o_ref, d_ref = cam.rays(cam.pixel_grid())
    assert np.array_equal(transform_vectors(cam.T_world_cam, d.reshape(-1, 3)), d_ref)
    valid = np.random.default_rng(1).random((256, 320)) < 0.3
    v, u = np.nonzero(valid)
    _, d_sub = cam.rays(np.column_stack([u, v]).astype(np.float64))
    assert np.array_equal(transform_vectors(cam.T_world_cam, d[valid]), d_sub)


def test_column_planes_contain_their_rays_without_distortion():
    proj = make_cam([0, 0, 0, 0, 0], size=(1280, 800))
    planes = proj.column_planes()
    assert planes.shape == (1280, 4)
    cols = np.array([0.0, 17.0, 640.0, 1279.0])
    rows = np.linspace(0, 799, 200)
    for c in cols:
        o, d = proj.rays(np.column_stack([np.full(rows.size, c), rows]))
        n, dd = planes[int(c), :3], planes[int(c), 3]
        for depth in (0.2, 0.5, 2.0):
            assert np.abs((o + depth * d) @ n + dd).max() <= 1e-9
    # Normals point towards increasing column numbers.
    o, d = proj.rays(np.array([[641.0, 400.0]]))
    assert (o + 0.5 * d) @ planes[640, :3] + planes[640, 3] > 0


def test_local_column_planes_contain_the_ray_with_distortion():
    proj = make_cam(DIST_MODELS["5"], size=(1280, 800))
    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(0, 1279, 500), rng.uniform(0, 799, 500)])
    planes = proj.column_planes(uv[:, 0], rows=uv[:, 1])
    o, d = proj.rays(uv)
    for depth in (0.3, 1.0):
        X = o + depth * d
        assert np.abs(np.sum(X * planes[:, :3], axis=1) + planes[:, 3]).max() <= 1e-9
    # The global least-squares plane is only an approximation under distortion: measure how far.
    rows = np.linspace(0, 799, 400)
    worst = 0.0
    for c in (0.0, 320.0, 640.0):
        pl = proj.column_planes([c])[0]
        o, d = proj.rays(np.column_stack([np.full(rows.size, c), rows]))
        worst = max(worst, np.abs((o + 0.5 * d) @ pl[:3] + pl[3]).max())
    assert 1e-6 < worst < 2e-3  # curved light surface: sub-mm but far from exact at 0.5 m


def test_json_round_trip_is_exact(tmp_path):
    cam = make_cam(DIST_MODELS["8 rational"])
    back = PinholeCamera.from_dict(json.loads(json.dumps(cam.to_dict())))
    for a in ("K", "dist", "T_world_cam"):
        assert np.array_equal(getattr(cam, a), getattr(back, a))
    assert (back.width, back.height, back.name) == (cam.width, cam.height, cam.name)
    cam.save(tmp_path / "cam.json")
    assert np.array_equal(PinholeCamera.load(tmp_path / "cam.json").K, cam.K)


def test_resized_keeps_the_field_of_view():
    cam = make_cam(DIST_MODELS["5"])
    small = cam.resized(640, 512)
    P = np.random.default_rng(2).uniform(-0.05, 0.05, (100, 3))
    big_uv, small_uv = cam.project(P), small.project(P)
    assert np.abs((big_uv + 0.5) * 0.5 - 0.5 - small_uv).max() < 1e-9


def test_bad_camera_fields_name_the_problem():
    with pytest.raises(ConfigError, match="'K'"):
        PinholeCamera(np.eye(2), 10, 10)
    with pytest.raises(ConfigError, match="no skew"):
        PinholeCamera(np.array([[100.0, 0.5, 5], [0, 100, 5], [0, 0, 1]]), 10, 10)
    with pytest.raises(ConfigError, match="4, 5, 8, 12 or 14"):
        PinholeCamera(np.eye(3), 10, 10, dist=[0.1, 0.2, 0.3])
    with pytest.raises(ConfigError, match="rigid"):
        PinholeCamera(np.eye(3), 10, 10, T_world_cam=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ConfigError, match=r"rig.json: projector: missing field"):
        PinholeCamera.from_dict({"K": np.eye(3).tolist()}, where="rig.json: projector")


@pytest.mark.parametrize("dist", [[0.1, -0.2, 1e-3, 2e-3, 0.05], [0.1, -0.05, 0, 0, 0.01, 0.02, -0.01, 0.003],
                                  [-0.3, 0.1, 1e-3, -2e-3, 0.01, 0.02, -0.01, 0.003, 1e-3, -1e-3, 2e-3, 5e-4]])
def test_compiled_distort_is_the_numpy_formula_bit_for_bit(dist):
    from rangekit.lens import COMPILED_DISTORT_POINTS, _distort_numpy, _full_coeffs, distort

    xy = np.random.default_rng(len(dist)).normal(0.0, 0.4, (COMPILED_DISTORT_POINTS + 7, 2))
    xy[::13] = np.nan                                   # NaN stays NaN
    xy[1, 0] = np.inf
    want = _distort_numpy(xy, _full_coeffs(np.asarray(dist, dtype=np.float64)))
    assert np.array_equal(distort(xy, dist), want, equal_nan=True)
    assert np.array_equal(distort(xy[:10], dist), want[:10], equal_nan=True)          # the numpy path, below the size
    assert np.array_equal(distort(xy[:, ::-1][:, ::-1], dist), want, equal_nan=True)   # a strided view is copied
