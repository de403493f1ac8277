"""Find attached hardware: serial ports (turntables, projectors) and depthai cameras.

Both functions are quick and never hang or abort. The depthai search is one bounded call,
``XLinkConnection.getAllConnectedDevices(timeoutMs=...)``, made on the calling thread: depthai stops
searching at the deadline itself. (An earlier version ran ``Device.getAllAvailableDevices()``, which
always searches for 500 ms, in a daemon thread abandoned at the deadline; when the interpreter exited
while that thread was still inside depthai's C++ code, the thread was torn down through a C++ frame
and the process died with ``terminate called without an active exception``, SIGABRT, exit 134.)
depthai is imported inside :func:`list_depthai_devices` only; :func:`open_depthai_device` (the search, then
``dai.Device``) takes the module from its caller.
"""

from __future__ import annotations

import math
import os
import time

from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError
from rangekit.rig.checks import MAX_SEARCH_S

__all__ = ["list_serial_ports", "list_depthai_devices", "search_depthai", "open_depthai_device",
           "check_search_timeout", "MAX_SEARCH_S"]

#: MAX_SEARCH_S (rangekit.rig.checks): the longest depthai search accepted, seconds.
#: The longest single depthai search call (seconds): a longer search is several calls.
SEARCH_CHUNK_S = 0.5


def list_serial_ports() -> list[dict]:
    """Serial ports, one dict each: ``device`` (e.g. "/dev/ttyUSB0"), ``description``, ``vid_pid``
    ("1A86:7523", or None for non-USB ports), ``serial_number`` (or None), ``manufacturer``.
    """
    from serial.tools import list_ports

    ports = []
    for p in sorted(list_ports.comports(), key=lambda p: p.device):
        vid_pid = f"{p.vid:04X}:{p.pid:04X}" if p.vid is not None and p.pid is not None else None
        ports.append({"device": p.device, "description": p.description, "vid_pid": vid_pid,
                      "serial_number": p.serial_number, "manufacturer": p.manufacturer})
    return ports


def check_search_timeout(timeout_s) -> None:
    """Raise ConfigError unless ``timeout_s`` is a finite number of seconds in 0..MAX_SEARCH_S."""
    if isinstance(timeout_s, bool) or not (isinstance(timeout_s, (int, float)) and math.isfinite(timeout_s)
                                           and 0 <= timeout_s <= MAX_SEARCH_S):
        raise ConfigError(f"depthai search timeout: expected seconds in 0..{MAX_SEARCH_S:g}, found {timeout_s!r}")


def search_depthai(dai, timeout_s: float) -> list:
    """``depthai.DeviceInfo`` of every device that answers within ``timeout_s`` seconds, in any state
    (``X_LINK_BOOTED`` = held by another program), each device once.

    The search runs on the calling thread as bounded calls to depthai's
    ``XLinkConnection.getAllConnectedDevices(timeoutMs=...)`` of at most :data:`SEARCH_CHUNK_S` each
    (depthai's own default search time), so depthai itself stops at the deadline and Ctrl-C is seen
    between chunks. Each call costs a few tens of milliseconds beyond its timeout: ``timeout_s = 0`` is
    one call that returns in about 0.03 s.

    Raises ConfigError for a timeout that is negative, not finite or over :data:`MAX_SEARCH_S`;
    RuntimeError (depthai's) if the search fails.
    """
    check_search_timeout(timeout_s)
    deadline = time.monotonic() + timeout_s
    found: dict[str, object] = {}
    while True:
        left = max(0.0, deadline - time.monotonic())
        for info in dai.XLinkConnection.getAllConnectedDevices(
                timeoutMs=int(math.ceil(min(left, SEARCH_CHUNK_S) * 1000))):
            found.setdefault(info.getDeviceId() or info.name, info)
        if time.monotonic() >= deadline:
            return list(found.values())


def list_depthai_devices(timeout_s: float = 1.0) -> list[dict]:
    """depthai devices that answer within ``timeout_s`` seconds of searching (0..:data:`MAX_SEARCH_S`).

    Each is a dict: ``device_id`` (MXID or IP, what :class:`DepthaiCamera` takes), ``name``, ``state``
    (e.g. "X_LINK_UNBOOTED"; "X_LINK_BOOTED" means another program holds it), ``protocol``
    ("X_LINK_USB_VSC", "X_LINK_TCP_IP"), ``platform``. Returns [] when none answers in time, when
    depthai is not installed, or when the search fails. Importing depthai the first time adds about
    0.6 s before the search starts (not counted in ``timeout_s``). Raises ConfigError for a bad timeout.
    """
    check_search_timeout(timeout_s)
    try:
        import depthai as dai
    except ImportError:
        return []
    try:
        infos = search_depthai(dai, timeout_s)
    except RuntimeError:
        return []
    return [{"device_id": info.getDeviceId(), "name": info.name, "state": info.state.name,
             "protocol": info.protocol.name, "platform": info.platform.name} for info in infos]


def open_depthai_device(dai, device_id: str | None, search_timeout_s: float):
    """Find the depthai device ``device_id`` (id, name or IP; None: the first free one) and open it:
    ``dai.Device``, for :class:`rangekit.drivers.depthai.camera.DepthaiCamera` and the stereo pair.

    The search polls, so the timeout holds on every call.

    depthai reads DEPTHAI_SEARCH_TIMEOUT once per process, at its first search, so the deadline here is
    enforced by polling :func:`rangekit.drivers.discovery.search_depthai`, each search bounded by the time
    left (at most 0.5 s), until the device is listed and free; a device that is rebooting after a previous
    ``close()`` shows up again within that time. Runs on the calling thread: nothing is left inside
    depthai when this returns or raises.
    """
    check_search_timeout(search_timeout_s)
    os.environ.setdefault("DEPTHAI_SEARCH_TIMEOUT", str(max(1, int(round(search_timeout_s * 1000)))))
    who = f"depthai device {device_id!r}" if device_id else "a depthai device"
    t0 = time.monotonic()
    deadline = t0 + search_timeout_s
    while True:
        try:
            infos = search_depthai(dai, min(0.5, max(0.0, deadline - time.monotonic())))
        except RuntimeError as exc:
            raise DeviceError(f"{who}: the device search failed: {exc}") from exc
        match = [i for i in infos if device_id is None or device_id in (i.getDeviceId(), i.name)]
        free = [i for i in match if i.state != dai.XLinkDeviceState.X_LINK_BOOTED]
        if free:
            break
        if time.monotonic() >= deadline:
            if match:
                found = f"; {match[0].getDeviceId()} is held by another program (state X_LINK_BOOTED)"
            else:
                found = f"; found only {[i.getDeviceId() for i in infos]}" if infos else ""
            raise DeviceDisconnected(f"{who}: none answered within search_timeout_s={search_timeout_s:g} s "
                                     f"(searched {time.monotonic() - t0:.2f} s){found}; check the USB/PoE cable "
                                     "and power and that no other program holds it, list devices with "
                                     "'rangekit devices', or raise the rig file's devices.camera.search_timeout_s")
        time.sleep(min(0.05, max(0.0, deadline - time.monotonic())))
    try:
        return dai.Device(free[0])
    except RuntimeError as exc:
        raise DeviceError(f"{who}: found {free[0].getDeviceId()} but could not open it: {exc}; close other "
                          "programs using it and replug it") from exc
