"""The uvc driver's controls at the kernel boundary: the V4L2 ioctls linuxpy builds, checked against the kernel's
request numbers and control ids, and a webcam that ignores or refuses a write.

No virtual V4L2 device exists on these machines, so the kernel is modelled at its boundary only: linuxpy's
``linuxpy.ioctl.ioctl`` calls ``fcntl.ioctl(fd, request, struct)``, and the test replaces the ``fcntl`` that module
uses by :class:`WebcamKernel`, which answers VIDIOC_QUERYCAP, VIDIOC_QUERYCTRL, VIDIOC_G_CTRL and VIDIOC_S_CTRL as
uvcvideo does for a webcam (a C920's control ranges) on the file descriptor of ``/dev/null`` (a real character
device, opened by the driver's own code). Everything above the syscall is the real code: the driver, linuxpy's
ctypes structures and request numbers. The request numbers below are computed from linux/videodev2.h's _IOWR and
_IOR definitions, not taken from linuxpy.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import glob

import pytest

from rangekit.errors import DeviceDisconnected, DeviceError
from rangekit.rig.camera_controls import CameraControls

linuxpy_ioctl = pytest.importorskip("linuxpy.ioctl")


def _ioc(direction: int, nr: int, size: int) -> int:
    return (direction << 30) | (size << 16) | (ord("V") << 8) | nr


VIDIOC_QUERYCAP = _ioc(2, 0, 104)          # _IOR('V', 0, struct v4l2_capability)
VIDIOC_G_CTRL = _ioc(3, 27, 8)             # _IOWR('V', 27, struct v4l2_control)
VIDIOC_S_CTRL = _ioc(3, 28, 8)             # _IOWR('V', 28, struct v4l2_control)
VIDIOC_QUERYCTRL = _ioc(3, 36, 68)         # _IOWR('V', 36, struct v4l2_queryctrl)
CID = {"exposure_auto": 0x009A0901, "exposure_absolute": 0x009A0902, "exposure_auto_priority": 0x009A0903,
       "gain": 0x00980913, "white_balance_automatic": 0x0098090C, "white_balance_temperature": 0x0098091A,
       "focus_automatic_continuous": 0x009A090C, "focus_absolute": 0x009A090A}
NAME = {v: k for k, v in CID.items()}
#: A Logitech C920's controls as uvcvideo reports them: (minimum, maximum, step, default, value).
C920 = {"exposure_auto": (0, 3, 1, 3, 3), "exposure_absolute": (3, 2047, 1, 250, 156),
        "exposure_auto_priority": (0, 1, 1, 0, 1), "gain": (0, 255, 1, 0, 64),
        "white_balance_automatic": (0, 1, 1, 1, 1), "white_balance_temperature": (2000, 6500, 1, 4000, 4000),
        "focus_automatic_continuous": (0, 1, 1, 1, 1), "focus_absolute": (0, 250, 5, 0, 30)}


class WebcamKernel:
    """uvcvideo's answers to the V4L2 control ioctls for one webcam (module docstring). ``ignores``: controls whose
    write is accepted and not kept (a webcam that ignores it); ``refuses``: control -> errno of a refused write;
    ``calls``: every (request, control name, value) seen."""

    def __init__(self, controls=None, *, ignores=(), refuses=None):
        self.table = dict(C920 if controls is None else controls)
        self.values = {k: v[4] for k, v in self.table.items()}
        self.ignores, self.refuses = set(ignores), dict(refuses or {})
        self.calls = []

    def ioctl(self, fd, request, arg=0, mutate=True):
        request &= 0xFFFFFFFF
        if request == VIDIOC_QUERYCAP:
            arg.driver, arg.card, arg.bus_info = b"uvcvideo", b"HD Pro Webcam C920", b"usb-0000:00:14.0-1"
            arg.capabilities, arg.device_caps = 0x84A00001, 0x04200001     # DEVICE_CAPS | STREAMING | VIDEO_CAPTURE
            return 0
        if request not in (VIDIOC_QUERYCTRL, VIDIOC_G_CTRL, VIDIOC_S_CTRL):
            return fcntl.ioctl(fd, request, arg, mutate)
        name = NAME.get(arg.id)
        kind = {VIDIOC_QUERYCTRL: "QUERYCTRL", VIDIOC_G_CTRL: "G_CTRL", VIDIOC_S_CTRL: "S_CTRL"}[request]
        self.calls.append((kind, name, getattr(arg, "value", None)))
        if name not in self.table:
            raise OSError(errno.EINVAL, "Invalid argument")
        lo, hi, step, default, _ = self.table[name]
        if kind == "QUERYCTRL":
            arg.name, arg.minimum, arg.maximum, arg.step, arg.default_value = name.encode(), lo, hi, step, default
        elif kind == "G_CTRL":
            arg.value = self.values[name]
        elif name in self.refuses:
            raise OSError(self.refuses[name], "refused")
        elif not lo <= arg.value <= hi:
            raise OSError(errno.ERANGE, "Numerical result out of range")
        elif name not in self.ignores:
            self.values[name] = arg.value
        return 0


@pytest.fixture
def kernel(monkeypatch):
    """Install a :class:`WebcamKernel` at linuxpy's syscall; the test may replace its table first."""
    k = WebcamKernel()
    monkeypatch.setattr(linuxpy_ioctl, "fcntl", k)
    return k


def _node():
    from rangekit.drivers.uvc.v4l2 import open_node

    return open_node("/dev/null")


def test_the_controls_are_written_modes_first_and_read_back(kernel):
    from rangekit.drivers.uvc.controls import apply_controls

    node = _node()
    try:
        assert (node.card, node.driver) == ("HD Pro Webcam C920", "uvcvideo")
        applied = apply_controls(node, CameraControls(exposure_us=33333.0, iso=400, white_balance_k=5600, focus=132))
    finally:
        node.close()
    writes = [(n, v) for kind, n, v in kernel.calls if kind == "S_CTRL"]
    assert writes == [("exposure_auto", 1), ("exposure_auto_priority", 0), ("white_balance_automatic", 0),
                      ("focus_automatic_continuous", 0),      # every automatic mode off before a value
                      ("exposure_absolute", 333),               # 100 us units
                      ("gain", 51),                             # ISO 400: 0 + 300 / 1500 * 255 = 51
                      ("white_balance_temperature", 5600), ("focus_absolute", 130)]   # 132 on the step of 5
    reads = [n for kind, n, _ in kernel.calls if kind == "G_CTRL"]
    assert reads == [n for n, _ in writes]                      # each read back
    assert applied.writes == tuple(writes) and applied.limits == ()
    assert {n: kernel.values[n] for n, _ in writes} == dict(writes)


def test_a_webcam_that_ignores_the_exposure_lock_is_refused_in_one_line(kernel):
    from rangekit.drivers.uvc.controls import apply_controls

    kernel.ignores = {"exposure_absolute"}
    node = _node()
    with pytest.raises(DeviceError) as exc:
        apply_controls(node, CameraControls())
    node.close()
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("uvc /dev/null: the camera ignores exposure_absolute: wrote 333, read back 156 "
                          "(capture.camera.exposure_us)")


def test_a_control_the_camera_refuses_is_one_line_naming_it(kernel):
    from rangekit.drivers.uvc.controls import apply_controls

    kernel.refuses = {"gain": errno.EIO}
    node = _node()
    with pytest.raises(DeviceError) as exc:
        apply_controls(node, CameraControls())
    node.close()
    assert "\n" not in str(exc.value)
    assert str(exc.value).startswith("uvc /dev/null: the camera refused gain = 0 (VIDIOC_S_CTRL: refused)")
    # a value outside the control's range is refused before anything is written
    node = _node()
    kernel.calls.clear()
    with pytest.raises(DeviceError, match=r"capture.camera.white_balance_k 9000 K is white_balance_temperature 9000, "
                                          r"outside the camera's range 2000..6500"):
        apply_controls(node, CameraControls(white_balance_k=9000))
    node.close()
    assert not [c for c in kernel.calls if c[0] == "S_CTRL"]


def test_automatic_modes_and_what_a_device_lacks(kernel):
    from rangekit.drivers.uvc.controls import apply_controls

    kernel.table = {k: v for k, v in C920.items() if not k.startswith("focus") and k != "gain"}
    kernel.values = {k: v[4] for k, v in kernel.table.items()}
    node = _node()
    try:
        applied = apply_controls(node, CameraControls(exposure_us=None, iso=None, white_balance_k=None, focus=None,
                                                      lock_focus=False))
    finally:
        node.close()
    assert applied.writes == (("exposure_auto", 3), ("white_balance_automatic", 1))   # aperture priority: UVC's auto
    assert applied.limits == ("gain: no gain control, the sensor's gain is the camera's own",
                              "focus: no focus control (a fixed-focus lens), the focus stays where it is")


def test_the_camera_checks_its_controls_before_any_frame(kernel):
    from rangekit.drivers.uvc.camera import UvcCamera

    kernel.ignores = {"focus_absolute"}
    with pytest.raises(DeviceError, match=r"^uvc /dev/null: the camera ignores focus_absolute: wrote 130, read back "
                                          r"30 \(capture.camera.focus\)"):
        UvcCamera("/dev/null", size=(64, 48), controls=CameraControls())
    kernel.ignores = set()
    kernel.table = {k: v for k, v in C920.items() if not k.startswith("exposure")}
    with pytest.raises(DeviceError, match=r"^uvc /dev/null: exposure: no exposure_auto control, the exposure cannot "
                                          r"be set or locked; coded light needs a locked exposure"):
        UvcCamera("/dev/null", size=(64, 48), controls=CameraControls(), coded_light=True)


def test_bad_device_paths_are_one_line_each(tmp_path):
    from rangekit.drivers.uvc.camera import UvcCamera

    cases = {"/dev/video97": (DeviceDisconnected, "uvc /dev/video97: no such device; is the webcam plugged in?"),
             97: (DeviceDisconnected, "uvc /dev/video97: no such device"),
             "/dev/null": (DeviceError, "uvc /dev/null: not a V4L2 video device (VIDIOC_QUERYCAP: Inappropriate "
                                        "ioctl for device)"),
             str(tmp_path): (DeviceError, f"uvc {tmp_path}: not a device node")}
    for source, (kind, start) in cases.items():
        with pytest.raises(kind) as exc:
            UvcCamera(source, size=(640, 480))
        assert str(exc.value).startswith(start) and "\n" not in str(exc.value), str(exc.value)


def test_list_cameras_lists_the_capture_nodes_present():
    from rangekit.drivers.uvc.camera import list_cameras

    if glob.glob("/dev/video*"):
        pytest.skip("this machine has V4L2 nodes: the list depends on them")
    assert list_cameras() == []


def test_the_structures_are_the_kernel_s():
    from linuxpy.video import raw

    assert ctypes.sizeof(raw.v4l2_control) == 8 and ctypes.sizeof(raw.v4l2_queryctrl) == 68
    assert ctypes.sizeof(raw.v4l2_capability) == 104
    assert raw.IOC.S_CTRL & 0xFFFFFFFF == VIDIOC_S_CTRL and raw.IOC.G_CTRL & 0xFFFFFFFF == VIDIOC_G_CTRL
    assert raw.IOC.QUERYCTRL & 0xFFFFFFFF == VIDIOC_QUERYCTRL and raw.IOC.QUERYCAP & 0xFFFFFFFF == VIDIOC_QUERYCAP
