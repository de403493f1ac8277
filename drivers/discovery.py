"""Find attached hardware: serial ports (turntables, projectors) and depthai cameras.

Both functions are quick and never hang: the depthai search runs in a daemon thread and is abandoned
after ``timeout_s``. depthai is imported inside :func:`list_depthai_devices` only.
"""

from __future__ import annotations

import threading

__all__ = ["list_serial_ports", "list_depthai_devices"]


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


def _depthai_devices(dai) -> list[dict]:
    return [{"device_id": info.getDeviceId(), "name": info.name, "state": info.state.name,
             "protocol": info.protocol.name, "platform": info.platform.name}
            for info in dai.Device.getAllAvailableDevices()]


def list_depthai_devices(timeout_s: float = 1.0) -> list[dict]:
    """depthai devices that answer within ``timeout_s`` seconds of searching.

    Each is a dict: ``device_id`` (MXID or IP, what :class:`DepthaiCamera` takes), ``name``, ``state``
    (e.g. "X_LINK_UNBOOTED"), ``protocol`` ("X_LINK_USB_VSC", "X_LINK_TCP_IP"), ``platform``.
    Returns [] when none answers in time, when depthai is not installed, or when the search fails; a
    search still running at the deadline is left to finish in a daemon thread. Importing depthai the
    first time adds about 0.6 s before the search starts (not counted in ``timeout_s``).
    """
    try:
        import depthai as dai
    except ImportError:
        return []
    result: list[dict] = []
    done = threading.Event()

    def search() -> None:
        try:
            result.extend(_depthai_devices(dai))
        except RuntimeError:
            pass
        finally:
            done.set()

    threading.Thread(target=search, name="depthai-discovery", daemon=True).start()
    if not done.wait(timeout_s):
        return []
    return list(result)
