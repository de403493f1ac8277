"""Find attached hardware: serial ports (turntables, projectors) and depthai cameras.

Both functions are quick and never hang or abort. The depthai search is one bounded call,
``XLinkConnection.getAllConnectedDevices(timeoutMs=...)``, made on the calling thread: depthai stops
searching at the deadline itself. (An earlier version ran ``Device.getAllAvailableDevices()``, which
always searches for 500 ms, in a daemon thread abandoned at the deadline; when the interpreter exited
while that thread was still inside depthai's C++ code, the thread was torn down through a C++ frame
and the process died with ``terminate called without an active exception``, SIGABRT, exit 134.)
depthai is imported inside :func:`list_depthai_devices` only.
"""

from __future__ import annotations

import math
import time

from rangekit.errors import ConfigError
from rangekit.rig.checks import MAX_SEARCH_S

__all__ = ["list_serial_ports", "list_depthai_devices", "search_depthai", "check_search_timeout",
           "MAX_SEARCH_S"]

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

