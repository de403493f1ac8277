"""The RealSense driver's infrared camera on the real pyrealsense2 stack: a software device in the SDK's pipeline
(tests/support/software_realsense.py), a recording written by the SDK's recorder and played back through the rig
file's ``devices.camera.bag``, and its bad input as one line each."""

import json
import time

import numpy as np
import pytest

rs = pytest.importorskip("pyrealsense2")

from support.software_realsense import SERIAL, SoftwareRealSense, record  # noqa: E402

from rangekit.camera import PinholeCamera  # noqa: E402
from rangekit.drivers import open_rig_devices  # noqa: E402
from rangekit.drivers.realsense.camera import RealSenseCamera, list_cameras, open_camera  # noqa: E402
from rangekit.errors import (ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout,  # noqa: E402
                             FileFormatError)
from rangekit.rig.camera_controls import CameraControls  # noqa: E402
from rangekit.rig.checks import CAMERA_TEMPLATES, validate_devices  # noqa: E402
from rangekit.rig.rig_file import Rig, load_rig, save_rig  # noqa: E402

W, H = 64, 48
CAMERA = PinholeCamera(np.array([[58.0, 0.0, 31.25], [0.0, 58.5, 23.75], [0.0, 0.0, 1.0]]), W, H, name="ir")


def brightness(exposure_us, gain, n):
    """Each frame's grey level follows the sensor's exposure and gain: what the driver sets shows in the pixels."""
    return np.full((H, W), min(255, int(exposure_us * gain / 16 / 100)), np.uint8)


@pytest.fixture()
def device():
    dev = SoftwareRealSense(CAMERA, infrared=brightness).start()
    yield dev
    dev.stop()


def rig_with(section, capture=None):
    return Rig(cameras=(CAMERA,), devices={"camera": section}, capture=capture or {})


def test_infrared_camera_controls_set_and_read_back_emitter_off(device):
    sec = {**CAMERA_TEMPLATES["realsense"], "serial": SERIAL}
    validate_devices({"camera": sec}, where="rig.json")
    rig = rig_with(sec, {"camera": {"exposure_us": 8000, "iso": 200, "fps": 30}})
    with open_camera(sec, rig, coded_light=True, where="rig.json", context=device.context) as cam:
        # the device's own options say what the driver set: auto off, exposure, ISO 200 = gain 32, emitter off
        assert (device.option(rs.option.enable_auto_exposure), device.option(rs.option.exposure),
                device.option(rs.option.gain), device.option(rs.option.emitter_enabled)) == (0, 8000, 32, 0)
        assert cam.read_back == {"enable_auto_exposure": 0, "exposure": 8000, "gain": 32, "emitter_enabled": 0}
        assert np.array_equal(cam.calibration.K, CAMERA.K) and cam.calibration.size == (W, H)
        assert not np.any(cam.calibration.dist)
        img = cam.capture()
        assert img.shape == (H, W) and img.dtype == np.uint8 and img[0, 0] == 160
        assert cam.last_frame_time is not None
        cam.set_controls(CameraControls(exposure_us=4000, iso=100, fps=30))
        assert cam.capture()[0, 0] == 40          # a frame exposed after the change
        with pytest.raises(ConfigError, match="locked exposure"):
            cam.set_controls(CameraControls(exposure_us=None))
    assert [c.id for c in list_cameras(context=device.context)] == [SERIAL]


def test_device_loss_is_a_timeout_then_reconnect_resumes(device):
    cam = RealSenseCamera(SERIAL, size=(W, H), frame_timeout_s=0.5, context=device.context)
    try:
        cam.capture()
        device.paused.set()                       # the camera stops sending frames
        with pytest.raises(DeviceTimeout) as err:
            cam.capture()
        assert "\n" not in str(err.value) and SERIAL in str(err.value) and "cable" in str(err.value)
        device.paused.clear()
        cam.reconnect(2.0)
        assert device.option(rs.option.exposure) == 33333 and device.option(rs.option.emitter_enabled) == 0
        assert cam.capture()[0, 0] == 255
    finally:
        cam.close()


def test_recording_plays_back_through_the_rig_file(tmp_path):
    dev = SoftwareRealSense(CAMERA, infrared=lambda e, g, n: np.full((H, W), n % 256, np.uint8)).start()
    try:
        record(dev, tmp_path / "scan.db3", 8, exposure_us=4000)
    finally:
        dev.stop()
    rig_file = tmp_path / "rig.json"
    save_rig(rig_with({"type": "realsense", "bag": "scan.db3"}), rig_file)  # relative to the rig file
    devices = open_rig_devices(load_rig(rig_file), where=str(rig_file), open_display=False, coded_light=False)
    cam = devices.camera
    try:
        assert cam.serial == SERIAL and cam.read_back["exposure"] == 4000 and cam.read_back["emitter_enabled"] == 0
        assert np.array_equal(cam.calibration.K, CAMERA.K)
        values = []
        with pytest.raises(DeviceError, match="no more frames") as err:
            while True:
                values.append(int(cam.capture()[0, 0]))
                time.sleep(0.05 if len(values) < 4 else 0.0)   # a reader slower than the recording: nothing dropped
        assert "\n" not in str(err.value)
        assert len(values) >= 8 and np.all(np.diff(values) == 1)   # every recorded frame, in order, none dropped
    finally:
        devices.close()


def test_bad_input_is_one_line_each(device, tmp_path):
    def line(exc_type, call):
        with pytest.raises(exc_type) as err:
            call()
        assert "\n" not in str(err.value)
        return str(err.value)

    msg = line(DeviceDisconnected, lambda: RealSenseCamera("000000000000", size=(W, H), search_timeout_s=0.2,
                                                            context=device.context))
    assert "000000000000" in msg and f"found only {SERIAL}" in msg
    (tmp_path / "notes.bag").write_text("not a bag")
    msg = line(FileFormatError, lambda: RealSenseCamera(bag=tmp_path / "notes.bag", size=(W, H)))
    assert "notes.bag" in msg and "not a RealSense recording" in msg
    msg = line(DeviceError, lambda: RealSenseCamera(SERIAL, size=(W, H), controls=CameraControls(iso=1600),
                                                    context=device.context))
    assert "capture.camera.iso 1600" in msg and "16..248" in msg
    msg = line(DeviceError, lambda: RealSenseCamera(SERIAL, size=(W + 1, H), context=device.context))
    assert f"{W}x{H} 30 fps" in msg
    msg = line(ConfigError, lambda: validate_devices({"camera": {"type": "realsense", "infrared": 3}}, where="rig.json"))
    assert "devices.camera.infrared" in msg
    msg = line(ConfigError, lambda: validate_devices({"camera": {"type": "realsense", "bag": "a.mp4"}},
                                                     where="rig.json"))
    assert "devices.camera.bag" in msg


def test_rig_init_writes_the_realsense_section(capsys):
    from rangekit.cli import main

    assert main(["rig", "init", "--camera", "realsense"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["devices"]["camera"] == CAMERA_TEMPLATES["realsense"]
    validate_devices(data["devices"], where="template")
