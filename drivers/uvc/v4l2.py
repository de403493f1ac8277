"""The kernel's V4L2 interface of a webcam, as the uvc driver needs it: open a node and check that it is a video
capture device (``VIDIOC_QUERYCAP``), query a control (``VIDIOC_QUERYCTRL``), write it (``VIDIOC_S_CTRL``) and read it
back (``VIDIOC_G_CTRL``); list the capture nodes present.

The ioctl structures and request numbers are linuxpy's (``linuxpy.video.raw``: ``v4l2_capability``,
``v4l2_queryctrl``, ``v4l2_control``; ``IOC``), and each request goes through ``linuxpy.ioctl.ioctl``, i.e.
``fcntl.ioctl`` on the node's file descriptor: the kernel boundary, where the tests put a model of a webcam
(tests/drivers/test_uvc_controls.py). linuxpy is imported inside the functions, so importing this module needs it
not. Every failure is a one-line :class:`~rangekit.errors.DeviceError` naming the node.
"""

from __future__ import annotations

import errno
import glob
import os
import stat
from dataclasses import dataclass

from rangekit.errors import DeviceDisconnected, DeviceError

__all__ = ["ControlInfo", "V4l2Node", "node_path", "open_node", "capture_nodes", "CONTROL_IDS"]

#: The V4L2 control ids the driver writes (linux/v4l2-controls.h), by the name docs/hardware.md uses.
CONTROL_IDS = {
    "exposure_auto": 0x009A0901,            # V4L2_CID_EXPOSURE_AUTO (menu: 0 auto, 1 manual, 3 aperture priority)
    "exposure_absolute": 0x009A0902,        # V4L2_CID_EXPOSURE_ABSOLUTE, units of 100 us
    "exposure_auto_priority": 0x009A0903,   # V4L2_CID_EXPOSURE_AUTO_PRIORITY: 0 = the frame rate is kept
    "gain": 0x00980913,                     # V4L2_CID_GAIN, the device's own units
    "white_balance_automatic": 0x0098090C,  # V4L2_CID_AUTO_WHITE_BALANCE
    "white_balance_temperature": 0x0098091A,  # V4L2_CID_WHITE_BALANCE_TEMPERATURE, kelvin
    "focus_automatic_continuous": 0x009A090C,  # V4L2_CID_FOCUS_AUTO
    "focus_absolute": 0x009A090A,           # V4L2_CID_FOCUS_ABSOLUTE, the device's own units
}
#: v4l2_capability.capabilities: the node's caps are in device_caps; VIDEO_CAPTURE (single-planar).
_CAP_DEVICE_CAPS, _CAP_VIDEO_CAPTURE = 0x80000000, 0x00000001
#: v4l2_queryctrl.flags: a control the device has but cannot take now.
_FLAG_DISABLED, _FLAG_READ_ONLY = 0x0001, 0x0004
_GONE = (errno.ENODEV, errno.ENXIO, errno.ESHUTDOWN)


@dataclass(frozen=True)
class ControlInfo:
    """A control as ``VIDIOC_QUERYCTRL`` describes it: its name, range, step and default (device units)."""

    name: str
    id: int
    minimum: int
    maximum: int
    step: int
    default: int
    flags: int

    @property
    def writable(self) -> bool:
        return not self.flags & (_FLAG_DISABLED | _FLAG_READ_ONLY)


def node_path(device) -> str:
    """The device node of a rig file's ``devices.camera.device``: an index N is ``/dev/videoN``, a path stays."""
    return f"/dev/video{device}" if isinstance(device, int) and not isinstance(device, bool) else str(device)


class V4l2Node:
    """An open V4L2 node (``open_node``): ``card`` its name, ``driver``, ``bus_info``; controls queried, written and
    read by name (:data:`CONTROL_IDS`). ``name`` ("uvc /dev/video0") prefixes every error."""

    def __init__(self, path: str, fd: int, caps) -> None:
        self.path, self.fd, self.name = path, fd, f"uvc {path}"
        self.card = caps.card.decode(errors="replace")
        self.driver = caps.driver.decode(errors="replace")
        self.bus_info = caps.bus_info.decode(errors="replace")

    def _ioctl(self, request_name: str, arg, what: str):
        from linuxpy.ioctl import ioctl
        from linuxpy.video.raw import IOC

        try:
            return ioctl(self.fd, getattr(IOC, request_name), arg)
        except OSError as exc:
            if exc.errno in _GONE:
                raise DeviceDisconnected(f"{self.name}: {what}: the device went away ({exc.strerror}); check its "
                                         "USB cable (was it unplugged?)") from exc
            raise

    def query(self, name: str) -> ControlInfo | None:
        """The control ``name`` (a key of :data:`CONTROL_IDS`), or None when the device has none."""
        from linuxpy.video import raw

        q = raw.v4l2_queryctrl()
        q.id = CONTROL_IDS[name]
        try:
            self._ioctl("QUERYCTRL", q, f"VIDIOC_QUERYCTRL {name}")
        except OSError as exc:
            if exc.errno == errno.EINVAL:
                return None
            raise DeviceError(f"{self.name}: VIDIOC_QUERYCTRL {name}: {exc.strerror}") from exc
        return ControlInfo(name, int(q.id), int(q.minimum), int(q.maximum), int(q.step), int(q.default_value),
                           int(q.flags))

    def read(self, name: str) -> int:
        """The control's current value (``VIDIOC_G_CTRL``)."""
        from linuxpy.video import raw

        c = raw.v4l2_control(CONTROL_IDS[name], 0)
        try:
            self._ioctl("G_CTRL", c, f"reading {name}")
        except OSError as exc:
            raise DeviceError(f"{self.name}: reading {name} (VIDIOC_G_CTRL) failed: {exc.strerror}") from exc
        return int(c.value)

    def write(self, name: str, value: int) -> None:
        """Write the control (``VIDIOC_S_CTRL``); a refusal is a DeviceError naming the control and the value."""
        from linuxpy.video import raw

        c = raw.v4l2_control(CONTROL_IDS[name], int(value))
        try:
            self._ioctl("S_CTRL", c, f"writing {name}")
        except OSError as exc:
            raise DeviceError(f"{self.name}: the camera refused {name} = {int(value)} (VIDIOC_S_CTRL: "
                              f"{exc.strerror}); check the value against `v4l2-ctl -d {self.path} -L`, and that no "
                              "other program holds the camera") from exc

    def close(self) -> None:
        fd, self.fd = self.fd, -1
        if fd >= 0:
            os.close(fd)


def open_node(path: str) -> V4l2Node:
    """Open the V4L2 node ``path`` read-write and check it is a video capture device.

    Raises DeviceDisconnected when it does not exist (a webcam not attached, or unplugged), DeviceError when it is
    not a character device, cannot be opened or is not a video capture device; each names the path and what to
    check."""
    from linuxpy.video import raw

    hint = "`rangekit devices` lists the webcams attached"
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise DeviceDisconnected(f"uvc {path}: no such device; is the webcam plugged in? {hint}") from None
    except OSError as exc:
        raise DeviceError(f"uvc {path}: cannot be read ({exc.strerror}); {hint}") from None
    if not stat.S_ISCHR(st.st_mode):
        raise DeviceError(f"uvc {path}: not a device node (a V4L2 webcam is a character device such as /dev/video0); "
                          f"{hint}")
    try:
        fd = os.open(path, os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        why = " (is your user in the 'video' group?)" if exc.errno == errno.EACCES else ""
        raise DeviceError(f"uvc {path}: cannot be opened: {exc.strerror}{why}; {hint}") from None
    caps = raw.v4l2_capability()
    try:
        from linuxpy.ioctl import ioctl

        ioctl(fd, raw.IOC.QUERYCAP, caps)
    except OSError as exc:
        os.close(fd)
        raise DeviceError(f"uvc {path}: not a V4L2 video device (VIDIOC_QUERYCAP: {exc.strerror}); {hint}") from None
    node_caps = caps.device_caps if caps.capabilities & _CAP_DEVICE_CAPS else caps.capabilities
    if not node_caps & _CAP_VIDEO_CAPTURE:
        os.close(fd)
        raise DeviceError(f"uvc {path}: a V4L2 node without video capture ({caps.card.decode(errors='replace')}: a "
                          "webcam's metadata node?); use its other /dev/videoN, " + hint)
    return V4l2Node(path, fd, caps)


def capture_nodes(pattern: str = "/dev/video*") -> list[V4l2Node]:
    """Every V4L2 video capture node present, opened (the caller closes them); nodes that are not, or that another
    user holds, are left out."""
    found = []
    for path in sorted(glob.glob(pattern), key=lambda p: (len(p), p)):
        try:
            found.append(open_node(path))
        except DeviceError:
            continue
    return found
