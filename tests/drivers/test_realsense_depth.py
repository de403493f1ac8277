"""The RealSense depth stream as a range sensor on the real pyrealsense2 stack: a software device feeding the Z16 frame
of a known plane, its depth and range maps checked against the exact answer and the SDK's own deprojection, and
``rangekit stereo --device --camera realsense --bag`` writing a recorded frame as a range map with its intrinsics."""

import numpy as np
import pytest

rs = pytest.importorskip("pyrealsense2")

from support.software_realsense import SERIAL, SoftwareRealSense, intrinsics, record  # noqa: E402

from rangekit.camera import PinholeCamera  # noqa: E402
from rangekit.drivers.realsense.depth import capture_range  # noqa: E402
from rangekit.rig.rig_file import load_rig  # noqa: E402

W, H = 64, 48
CAMERA = PinholeCamera(np.array([[58.0, 0.0, 31.25], [0.0, 58.5, 23.75], [0.0, 0.0, 1.0]]), W, H, name="depth")
NORMAL = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
OFFSET = 0.7                 # the plane n . X = 0.7 m, in the camera frame


def rays():
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return np.stack([(u - CAMERA.K[0, 2]) / CAMERA.K[0, 0], (v - CAMERA.K[1, 2]) / CAMERA.K[1, 1], np.ones_like(u)], -1)


def plane_z16(n=0):
    """The plane's depth in millimetres, as a D4xx's Z16 frame; a block of no-match pixels (0)."""
    z16 = np.rint(OFFSET / (rays() @ NORMAL) * 1000).astype(np.uint16)
    z16[5:9, 10:20] = 0
    return z16


@pytest.fixture()
def plane():
    dev = SoftwareRealSense(CAMERA, depth=plane_z16).start()
    yield dev
    dev.stop()


def test_depth_frame_is_a_range_map_of_the_plane(plane):
    frame = capture_range(SERIAL, size=(W, H), laser_power=0.5, context=plane.context)
    assert plane.option(rs.option.emitter_enabled) == 1 and frame.emitter == 1      # active stereo: emitter on
    assert plane.option(rs.option.laser_power) == 180                                # half of 0..360
    assert np.array_equal(frame.camera.K, CAMERA.K) and frame.depth_units == 0.001
    z16 = plane_z16()
    hole = z16 == 0
    assert np.all(np.isnan(frame.depth[hole])) and np.all(np.isnan(frame.range[hole]))
    exact_depth = z16 * 0.001
    exact_range = exact_depth * np.linalg.norm(rays(), axis=-1)
    assert np.allclose(frame.depth[~hole], exact_depth[~hole], rtol=0, atol=1e-12)
    assert np.allclose(frame.range[~hole], exact_range[~hole], rtol=0, atol=1e-12)
    # the SDK's own deprojection of a few pixels gives the same ranges (float32)
    intr = intrinsics(CAMERA)
    for u, v in ((0, 0), (63, 47), (31, 12), (50, 40)):
        p = rs.rs2_deproject_pixel_to_point(intr, [float(u), float(v)], float(exact_depth[v, u]))
        assert np.linalg.norm(p) == pytest.approx(frame.range[v, u], rel=1e-6)
    # and the points lie on the plane within the millimetre quantisation of z (half a unit, along the ray)
    points = frame.range[..., None] * rays() / np.linalg.norm(rays(), axis=-1, keepdims=True)
    assert np.nanmax(np.abs(points @ NORMAL - OFFSET)) <= 0.5e-3 * np.max(rays() @ NORMAL) + 1e-12


def test_cli_writes_a_recorded_depth_frame_as_a_range_map(tmp_path, capsys):
    from rangekit.cli import main

    dev = SoftwareRealSense(CAMERA, depth=plane_z16).start()
    try:
        record(dev, tmp_path / "plane.db3", 3, emitter=1)
    finally:
        dev.stop()
    out = tmp_path / "out"
    assert main(["stereo", "--device", "--camera", "realsense", "--bag", str(tmp_path / "plane.db3"), "--size",
                 f"{W}x{H}", "--out", str(out)]) == 0
    rig = load_rig(out / "rig.json")
    assert np.array_equal(rig.camera.K, CAMERA.K) and rig.devices["camera"]["serial"] == SERIAL
    depth, rng = np.load(out / "depth.npy"), np.load(out / "range.npy")
    z16 = plane_z16()
    assert np.array_equal(np.isnan(depth), z16 == 0)
    assert np.allclose(rng[z16 > 0], (z16 * 0.001 * np.linalg.norm(rays(), axis=-1))[z16 > 0], rtol=0, atol=1e-12)
    assert (out / "cloud.ply").is_file()
    # bad input: a recording and a serial at once, one line
    capsys.readouterr()
    assert main(["stereo", "--device", "--camera", "realsense", "--bag", "x.db3", "--device-id", "1", "--out",
                 str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err.strip()
    assert "give one" in err and "\n" not in err
