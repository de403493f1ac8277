"""The depthai driver without hardware: lazy import, API names, offline calibration conversion, discovery.

The calibration tests build a ``depthai.CalibrationHandler`` in code with known values, save it to JSON
with ``eepromToJsonFile`` and load it back with ``CalibrationHandler(path)``, exactly as a calibration
dumped from a real device would be read.
"""

import subprocess
import sys
import time

import numpy as np
import pytest

from rangekit.errors import ConfigError, DeviceError

DIST_A = [0.1, -0.2, 0.001, 0.002, 0.03, 0.01, 0.02, 0.003, 1e-4, 2e-4, 3e-4, 4e-4, 0.0, 0.0]
K_A = [[800.0, 0.0, 640.3], [0.0, 810.0, 399.1], [0.0, 0.0, 1.0]]  # calibrated at 1280 x 800
K_MONO = [[790.0, 0.0, 641.0], [0.0, 790.0, 401.0], [0.0, 0.0, 1.0]]
ANGLE = np.radians(1.0)  # CAM_C -> CAM_A rotation about y
R_AC = np.array([[np.cos(ANGLE), 0, np.sin(ANGLE)], [0, 1, 0], [-np.sin(ANGLE), 0, np.cos(ANGLE)]])


def _run(code: str, timeout: float = 30.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)


def test_importing_the_driver_does_not_import_depthai():
    res = _run("import sys, rangekit.drivers.depthai.camera, rangekit.drivers.discovery, rangekit.cli\n"
               "print('depthai' in sys.modules)")
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "False"


def test_every_depthai_name_exists():
    dai = pytest.importorskip("depthai")
    from rangekit.drivers.depthai.camera import DEPTHAI_NAMES

    from support.depthai_names import missing_names

    missing = missing_names(dai, DEPTHAI_NAMES)
    assert not missing, f"depthai {dai.__version__} lacks {missing}"


@pytest.fixture(scope="module")
def handler(tmp_path_factory):
    """CAM_A colour + CAM_B/CAM_C stereo pair (7.5 cm baseline), CAM_D with a tilted-sensor lens."""
    dai = pytest.importorskip("depthai")
    S = dai.CameraBoardSocket
    h = dai.CalibrationHandler()
    for sock, K in ((S.CAM_A, K_A), (S.CAM_B, K_MONO), (S.CAM_C, K_MONO), (S.CAM_D, K_MONO)):
        h.setCameraIntrinsics(sock, K, dai.Size2f(1280, 800))
        h.setCameraType(sock, dai.CameraModel.Perspective)
        h.setDistortionCoefficients(sock, DIST_A if sock == S.CAM_A else [0.0] * 14)
    h.setDistortionCoefficients(S.CAM_D, [0.0] * 12 + [0.01, 0.0])
    eye = np.eye(3).tolist()
    # depthai stores T_dst_src, in centimetres: left -> right is (-7.5, 0, 0) cm on an OAK-D.
    h.setCameraExtrinsics(S.CAM_B, S.CAM_C, eye, [-7.5, 0.0, 0.0], [-7.5, 0.0, 0.0])
    h.setCameraExtrinsics(S.CAM_C, S.CAM_A, R_AC.tolist(), [3.75, 0.0, 0.0], [3.75, 0.0, 0.0])
    path = tmp_path_factory.mktemp("calib") / "calib.json"
    assert h.eepromToJsonFile(str(path))
    return dai.CalibrationHandler(str(path))


def test_intrinsics_rescaled_with_pixel_centres(handler):
    import depthai as dai

    from rangekit.drivers.depthai.camera import pinhole_from_calibration

    full = pinhole_from_calibration(handler, "CAM_A", (1280, 800))
    np.testing.assert_allclose(full.K, K_A, atol=1e-4)
    half = pinhole_from_calibration(handler, "CAM_A", (640, 400))
    assert (half.width, half.height) == (640, 400)
    np.testing.assert_allclose([half.K[0, 0], half.K[1, 1]], [400.0, 405.0], atol=1e-4)
    # Pixel-centre convention: c' = (c + 0.5) * s - 0.5.
    np.testing.assert_allclose(half.K[:2, 2], [(640.3 + 0.5) / 2 - 0.5, (399.1 + 0.5) / 2 - 0.5], atol=1e-4)
    # depthai's own rescaling uses c' = c * s: ours differs by (s - 1) / 2 = -0.25 px.
    K_dai = np.asarray(handler.getCameraIntrinsics(dai.CameraBoardSocket.CAM_A, 640, 400))
    np.testing.assert_allclose(half.K[:2, 2] - K_dai[:2, 2], [-0.25, -0.25], atol=1e-4)
    # Same as resizing the full-size camera.
    np.testing.assert_allclose(half.K, full.resized(640, 400).K, atol=1e-9)
    # Other aspect ratio: ImgResizeMode.CROP keeps the scale and crops 40 rows top and bottom.
    crop = pinhole_from_calibration(handler, "CAM_A", (1280, 720))
    np.testing.assert_allclose(crop.K[:2, 2], [640.3, 399.1 - 40.0], atol=1e-4)
    np.testing.assert_allclose(crop.K[0, 0], 800.0, atol=1e-4)


def test_distortion_mapped(handler):
    from rangekit.drivers.depthai.camera import pinhole_from_calibration

    cam = pinhole_from_calibration(handler, "CAM_A", (640, 400))
    assert cam.dist.shape == (14,)
    np.testing.assert_allclose(cam.dist, DIST_A, rtol=1e-6, atol=1e-9)  # stored as float32


def test_tilted_lens_refused(handler):
    from rangekit.drivers.depthai.camera import pinhole_from_calibration

    with pytest.raises(ConfigError, match="CAM_D.*tilted"):
        pinhole_from_calibration(handler, "CAM_D", (640, 400))
    with pytest.raises(ConfigError, match="CAM_E.*not present"):
        pinhole_from_calibration(handler, "CAM_E", (640, 400))
    with pytest.raises(ConfigError, match="RGB"):
        pinhole_from_calibration(handler, "RGB", (640, 400))


def test_rig_extrinsics_in_metres(handler, tmp_path):
    from rangekit.drivers.depthai.camera import calibration_to_rig
    from rangekit.rig.rig_file import load_rig, save_rig

    rig = calibration_to_rig(handler, size=(640, 400), sockets=("CAM_A", "CAM_B", "CAM_C"), device_id="X")
    a, b, c = rig.cameras
    np.testing.assert_allclose(a.T_world_cam, np.eye(4))
    np.testing.assert_allclose(c.T_world_cam[:3, :3], R_AC, atol=1e-6)
    np.testing.assert_allclose(c.T_world_cam[:3, 3], [0.0375, 0, 0], atol=1e-7)
    # The 7.5 cm baseline is 0.075 m; the left camera (CAM_B) is 7.5 cm to the left of the right one.
    np.testing.assert_allclose(np.linalg.norm(b.center - c.center), 0.075, atol=1e-7)
    np.testing.assert_allclose(c.T_cam_world @ np.r_[b.center, 1.0], [-0.075, 0, 0, 1], atol=1e-7)
    assert [cam.name for cam in rig.cameras] == ["CAM_A", "CAM_B", "CAM_C"]
    assert rig.devices["depthai"]["device_id"] == "X"
    save_rig(rig, tmp_path / "rig.json")
    np.testing.assert_allclose(load_rig(tmp_path / "rig.json").cameras[2].T_world_cam, c.T_world_cam)


def test_list_depthai_devices_respects_timeout():
    pytest.importorskip("depthai")
    from rangekit.drivers.discovery import list_depthai_devices, list_serial_ports

    import depthai  # noqa: F401  (import time is not part of the search timeout)

    t0 = time.monotonic()
    found = list_depthai_devices(timeout_s=1.0)
    assert time.monotonic() - t0 < 1.5
    assert isinstance(found, list)
    assert all(isinstance(p["device"], str) for p in list_serial_ports())


def test_cli_devices_never_hangs():
    # A hang guard, not a speed figure: _run's 30 s timeout fails the test (the search itself is bounded at 1 s;
    # a loaded machine took 9 s to start Python and import, so no wall-clock figure is asserted).
    res = _run("from rangekit.cli import main; raise SystemExit(main(['devices']))")
    assert res.returncode == 0, res.stderr
    assert "serial ports" in res.stdout and "depthai cameras" in res.stdout


@pytest.mark.hardware
def test_open_device_or_skip_quickly():
    pytest.importorskip("depthai")
    from rangekit.drivers.depthai.camera import DepthaiCamera

    t0 = time.monotonic()
    try:
        cam = DepthaiCamera(search_timeout_s=0.5, size=(640, 400), depth=True)
    except DeviceError as exc:
        elapsed = time.monotonic() - t0
        assert elapsed < 3.0, f"giving up on a missing device took {elapsed:.1f} s"
        pytest.skip(f"no depthai device answered ({elapsed:.1f} s): {exc}")
    with cam:
        K = cam.calibration.K
        assert K[0, 0] > 0 and cam.calibration.size == (640, 400)
        frame = cam.capture()
        assert frame.shape == (400, 640, 3) and frame.dtype == np.uint8
        try:
            depth = cam.depth()
        except DeviceError:
            return  # a model without a stereo pair
        assert depth.dtype == np.float32 and depth.shape == (400, 640)
        assert np.all((depth[np.isfinite(depth)] > 0.05) & (depth[np.isfinite(depth)] < 50.0))
