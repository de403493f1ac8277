"""Camera controls from the rig file to a depthai device, and the rig file's new fields.

A fake ``depthai`` module (tests only, tests/support/fake_depthai.py) stands at the API boundary: it is put in
``sys.modules`` before the driver imports depthai and records every call the driver makes on it, so the tests read
exactly which commands a real OAK camera would receive. The names the fake offers are checked against the installed
depthai by tests/drivers/test_depthai_driver.py (``DEPTHAI_NAMES``), and :func:`test_mapping_on_real_depthai`
applies the same mapping to a real ``depthai.CameraControl`` message.
"""

import copy
import datetime

import pytest

from support.fake_depthai import FakeDepthai
from rangekit.rig.camera_controls import CameraControls
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError
from rangekit.rig.rig_file import Rig, template_rig
from rangekit.rig.checks import validate_rig_for_hardware


@pytest.fixture
def dai_log(monkeypatch):
    """The fake depthai in sys.modules; yields the list of calls made on it."""
    log = []
    FakeDepthai(log).install(monkeypatch)
    monkeypatch.setenv("DEPTHAI_SEARCH_TIMEOUT", "1")
    return log


def _initial(log):
    return [(m, a) for who, m, a in log if who == "initialControl CAM_A"]


def _rig(**camera):
    data = template_rig()
    data["devices"] = {"camera": dict(data["devices"]["camera"], search_timeout_s=0.0),
                       "projector": {"display": 1, "refresh_hz": 60.0}}
    data["capture"]["camera"].update(camera)
    return Rig.from_dict(data)


# ----------------------------------------------------------------------------- the driver
def test_rig_controls_reach_the_device_as_documented(dai_log):
    """The rig file's capture.camera, opened through open_rig_devices as a scan does (a projector display
    means coded light): the exact depthai commands, before the pipeline starts, and no StereoDepth."""
    from rangekit.drivers import open_rig_devices

    rig = _rig(exposure_us=16667, iso=400, white_balance_k=4500, focus=120, fps=20.0)
    devices = open_rig_devices(rig, where="rig.json", open_display=False, coded_light=True)
    cam = devices.camera
    assert _initial(dai_log) == [
        ("setManualExposure", (16667, 400)),
        ("setAutoWhiteBalanceMode", (cam._dai.CameraControl.AutoWhiteBalanceMode.OFF,)),
        ("setManualWhiteBalance", (4500,)),
        ("setAutoFocusMode", (cam._dai.CameraControl.AutoFocusMode.OFF,)),
        ("setManualFocus", (120,)),
    ]
    assert ("Camera", "build", ("CAM_A", 20.0)) in dai_log
    assert ("Camera", "requestOutput", ((1280, 800), "RGB888i", "CROP", 20.0)) in dai_log
    # The rig's devices.camera.search_timeout_s (0 s) reached the search: one call of 0 ms.
    assert [a for who, m, a in dai_log if who == "xlink"] == [(0,)]
    # Controls are in place before the pipeline starts; coded light starts no StereoDepth.
    order = [(who, m) for who, m, _ in dai_log]
    assert order.index(("Pipeline", "start")) > max(i for i, (w, _) in enumerate(order) if w.startswith("initial"))
    assert not any(who == "StereoDepth" for who, _, _ in dai_log)
    assert cam.capture().shape == (800, 1280, 3)
    with pytest.raises(DeviceError, match="stereo depth is not running"):
        cam.depth()
    devices.close()
    assert dai_log[-1] == ("device", "close", ())


def test_stereo_depth_only_when_asked(dai_log):
    from rangekit.drivers.depthai.camera import DepthaiCamera

    DepthaiCamera(search_timeout_s=0).close()
    assert not any(who == "StereoDepth" for who, _, _ in dai_log)
    cam = DepthaiCamera(search_timeout_s=0, depth=True)
    assert sum(who == "StereoDepth" for who, _, _ in dai_log) == 1
    assert cam.depth().shape == (800, 1280)
    cam.close()


def test_auto_modes_and_mono(dai_log):
    """Unlocked controls map to depthai's auto modes; 'mono' gives grey frames with the balance held."""
    from rangekit.drivers.depthai.camera import DepthaiCamera

    dai = __import__("sys").modules["depthai"]
    controls = CameraControls(exposure_us=None, iso=800, white_balance_k=None, focus=None, lock_focus=True)
    DepthaiCamera(search_timeout_s=0, controls=controls).close()
    assert _initial(dai_log) == [("setAutoExposureEnable", ()), ("setAutoExposureMaxISO", (800,)),
                                 ("setAutoWhiteBalanceMode", (dai.CameraControl.AutoWhiteBalanceMode.AUTO,)),
                                 ("setAutoFocusMode", (dai.CameraControl.AutoFocusMode.AUTO,)),
                                 ("setAutoFocusTrigger", ())]
    dai_log.clear()
    DepthaiCamera(search_timeout_s=0).close()  # no controls: everything automatic, refocusing
    assert _initial(dai_log)[-1] == ("setAutoFocusMode", (dai.CameraControl.AutoFocusMode.CONTINUOUS_VIDEO,))
    dai_log.clear()
    cam = DepthaiCamera(search_timeout_s=0, controls=CameraControls(white_balance_k=None, mono=True))
    assert ("setAutoWhiteBalanceLock", (True,)) in _initial(dai_log)
    assert ("Camera", "requestOutput", ((1280, 800), "GRAY8", "CROP", 30.0)) in dai_log
    assert cam.capture().shape == (800, 1280)
    cam.close()


def test_auto_exposure_refused_for_coded_light_unless_allowed(dai_log):
    from rangekit.drivers import open_rig_devices
    from rangekit.drivers.depthai.camera import DepthaiCamera

    auto = _rig(exposure_us="auto")  # refresh_hz does not constrain auto-exposure
    with pytest.raises(ConfigError, match=r"rig.json: capture.camera.exposure_us: coded light needs a locked"):
        open_rig_devices(auto, where="rig.json", open_display=False, coded_light=True)
    assert dai_log == []  # refused before any device was searched for
    devices = open_rig_devices(auto, where="rig.json", open_display=False, coded_light=False)
    assert _initial(dai_log)[0] == ("setAutoExposureEnable", ())
    devices.close()
    allowed = _rig(exposure_us="auto", allow_auto_exposure=True)
    open_rig_devices(allowed, where="rig.json", open_display=False, coded_light=True).close()
    # set_controls keeps the refusal, and refuses what only opening can change.
    cam = DepthaiCamera(search_timeout_s=0, controls=CameraControls(), coded_light=True, where="rig.json")
    with pytest.raises(ConfigError, match="coded light needs a locked exposure"):
        cam.set_controls(CameraControls(exposure_us=None))
    with pytest.raises(DeviceError, match=r"capture.camera.fps is set when the camera is opened \(30.0\), found 60"):
        cam.set_controls(CameraControls(exposure_us=16667, fps=60.0))
    cam.close()


def test_set_controls_sends_one_message(dai_log):
    from rangekit.drivers.depthai.camera import DepthaiCamera

    cam = DepthaiCamera(search_timeout_s=0, controls=CameraControls())
    dai_log.clear()
    new = CameraControls(exposure_us=8333.4, iso=1600, white_balance_k=3200, focus=200)
    cam.set_controls(new)
    assert [(m, a) for who, m, a in dai_log if who == "control"][::2] == [
        ("setManualExposure", (8333, 1600)), ("setManualWhiteBalance", (3200,)), ("setManualFocus", (200,))]
    assert [m for who, m, _ in dai_log if who == "inputControl"] == ["send"]
    assert cam.controls == new
    cam.close()


def test_impossible_controls_refused(dai_log):
    from rangekit.drivers.depthai.camera import DepthaiCamera

    with pytest.raises(DeviceError, match=r"exposure_us 50000 us is longer than a frame at capture.camera.fps 30"):
        DepthaiCamera(search_timeout_s=0, controls=CameraControls(exposure_us=50000))
    with pytest.raises(DeviceError, match="iso 'auto' with a manual exposure_us"):
        DepthaiCamera(search_timeout_s=0, controls=CameraControls(iso=None))
    assert dai_log[-1] == ("device", "close", ())  # opened, refused, closed again


def test_not_found_names_the_rig_field(dai_log, monkeypatch):
    from rangekit.drivers.depthai.camera import DepthaiCamera

    dai = __import__("sys").modules["depthai"]
    monkeypatch.setattr(dai.XLinkConnection, "getAllConnectedDevices", lambda timeoutMs: [])
    with pytest.raises(DeviceDisconnected, match="raise the rig file's devices.camera.search_timeout_s"):
        DepthaiCamera(search_timeout_s=0)


def test_mapping_on_real_depthai():
    """The mapping on a real depthai.CameraControl: the message holds what the fake recorded."""
    dai = pytest.importorskip("depthai")
    from rangekit.drivers.depthai.controls import apply_controls

    ctrl = dai.CameraControl()
    apply_controls(ctrl, CameraControls(exposure_us=16667, iso=400, white_balance_k=4500, focus=120), dai, name="x")
    assert ctrl.getExposureTime() == datetime.timedelta(microseconds=16667) and ctrl.getSensitivity() == 400
    assert ctrl.awbMode == dai.CameraControl.AutoWhiteBalanceMode.OFF
    assert ctrl.autoFocusMode == dai.CameraControl.AutoFocusMode.OFF and ctrl.getLensPosition() == 120


# ----------------------------------------------------------------------------- the rig file
@pytest.mark.parametrize("path, value, expected", [
    ("capture.camera.exposure_us", 0, r"capture.camera.exposure_us: expected a number 1.0..1000000.0"),
    ("capture.camera.exposure_us", "manual", r"capture.camera.exposure_us: .* found 'manual'"),
    ("capture.camera.iso", 50, r"capture.camera.iso: expected an integer 100..1600 \(ISO\) or 'auto', found 50"),
    ("capture.camera.iso", 200.5, r"capture.camera.iso: expected an integer"),
    ("capture.camera.white_balance_k", 20000, r"capture.camera.white_balance_k: .* or 'auto' or 'mono', found 20000"),
    ("capture.camera.focus", 300, r"capture.camera.focus: expected an integer 0..255"),
    ("capture.camera.lock_focus", "yes", r"capture.camera.lock_focus: expected true or false, found 'yes'"),
    ("capture.camera.fps", 0, r"capture.camera.fps: expected a number 0.1..120.0"),
    ("capture.camera.allow_auto_exposure", 1, r"capture.camera.allow_auto_exposure: expected true or false"),
    ("capture.camera.gain", 2, r"capture.camera.gain: unknown field"),
    ("capture.camera", [], r"capture.camera: expected an object"),
    ("devices.projector.refresh_hz", 0, r"devices.projector.refresh_hz: must be a number of hertz .* from 1 to 480, "
                                        "found 0"),
    ("devices.projector.refresh_hz", 600, r"devices.projector.refresh_hz: .*found 600"),
    ("devices.projector.refresh_hz", "60", r"devices.projector.refresh_hz: .*found '60'"),
    ("devices.projector.refresh_hz", True, r"devices.projector.refresh_hz: .*found True"),
    ("devices.camera.search_timeout_s", -1, r"devices.camera.search_timeout_s: must be a number of seconds .* from 0 "
                                            "to 600, found -1"),
    ("devices.camera.search_timeout_s", float("nan"), r"devices.camera.search_timeout_s: .*found nan"),
])
def test_bad_new_fields_name_file_and_field(path, value, expected):
    data = template_rig()
    *parents, key = path.split(".")
    sec = data
    for p in parents:
        sec = sec[p]
    sec[key] = value
    with pytest.raises(ConfigError, match=f"^rig.json: {expected}"):
        validate_rig_for_hardware(Rig.from_dict(copy.deepcopy(data)), where="rig.json")


def test_dlp_refresh_check():
    """At 60 Hz, 20000 us (1.2 periods) is refused naming the neighbours; 33333 us (2 periods) passes; no
    refresh_hz, or auto-exposure, is not checked."""
    data = template_rig()
    data["capture"]["camera"]["exposure_us"] = 20000
    with pytest.raises(ConfigError, match=r"^rig.json: capture.camera.exposure_us: expected a whole number of the "
                       r"projector's refresh periods \(16666.7 us at devices.projector.refresh_hz 60\), found 20000 us "
                       r"= 1.200 periods; use 16667 or 33333$"):
        validate_rig_for_hardware(Rig.from_dict(data), where="rig.json")
    for exposure in (33333, 16667, 50000):
        data["capture"]["camera"]["exposure_us"] = exposure
        validate_rig_for_hardware(Rig.from_dict(data), where="rig.json")
    data["capture"]["camera"]["exposure_us"] = 20000
    del data["devices"]["projector"]["refresh_hz"]
    validate_rig_for_hardware(Rig.from_dict(data), where="rig.json")


def test_template_shows_the_locked_defaults():
    data = template_rig()
    assert data["capture"]["camera"] == CameraControls().to_dict()
    assert data["devices"]["projector"]["refresh_hz"] == 60.0
    assert data["devices"]["camera"]["search_timeout_s"] == 3.0
