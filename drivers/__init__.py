"""Real hardware drivers: serial turntables (Horus, FabScan), projector control (ESC/VP21, PJLink),
a full-screen projector display (pygame, optional) and Luxonis depthai cameras.

``open_rig_devices(rig)`` opens what a rig file's ``devices`` section names (every field: docs/rig.md)::

    "devices": {
      "turntable": {"protocol": "horus" | "fabscan", "port": "/dev/ttyUSB0", "baud": 115200},
      "projector": {"display": 1, "control": {"protocol": "escvp21" | "pjlink", "port": "/dev/ttyUSB1"}},
      "camera": {"type": "depthai", "id": null, "socket": "CAM_A"}
    }

:func:`validate_rig_for_hardware` (``devices`` and ``capture``) runs first and opens nothing, so a typo in
the rig file is reported before any device moves. Any section may instead be ``{"type": "sim"}`` (not
opened here; the simulator provides it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from rangekit.errors import ConfigError

__all__ = ["HardwareRig", "open_rig_devices", "validate_devices", "validate_capture", "validate_rig_for_hardware",
           "DEVICE_FIELDS", "CAPTURE_FIELDS"]

#: Allowed fields of each object in a rig file's ``devices`` section, by dotted path.
DEVICE_FIELDS = {
    "devices": ("turntable", "projector", "camera", "depthai"),
    "devices.turntable": ("type", "protocol", "port", "baud"),
    "devices.projector": ("type", "display", "control"),
    "devices.projector.control": ("protocol", "port", "baud", "timeout", "password"),
    "devices.camera": ("type", "id", "socket"),
    "devices.depthai": ("device_id", "sockets", "size"),  # written by depthai_camera.calibration_to_rig
}
#: The ``capture`` settings: name -> (smallest, largest allowed value, unit). ``bits`` (8 or 16, the bit
#: depth of the captures) is written by the simulator's default rig and read by nothing yet.
CAPTURE_FIELDS = {
    "pattern_delay_s": (0.0, 10.0, "seconds"),
    "turntable_settle_s": (0.0, 60.0, "seconds"),
    "bits": (8, 16, "bits per pixel"),
}


def _error(where: str, path: str, problem: str) -> ConfigError:
    return ConfigError(f"{where}: {path}: {problem}")


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _object(value, where: str, path: str) -> dict:
    """``value`` must be a JSON object whose keys are all in DEVICE_FIELDS[path]."""
    if not isinstance(value, dict):
        raise _error(where, path, f"must be an object ({{...}}), found {_show(value)}")
    allowed = DEVICE_FIELDS[path]
    unknown = [k for k in value if k not in allowed]
    if unknown:
        raise _error(where, f"{path}.{unknown[0]}", f"unknown field; {path} has only {', '.join(allowed)}")
    return value


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _port(sec: dict, where: str, path: str, what: str) -> None:
    if "port" not in sec:
        raise _error(where, f"{path}.port", f"missing: name the {what}")
    if not isinstance(sec["port"], str) or not sec["port"].strip():
        raise _error(where, f"{path}.port", f"must be a non-empty string ({what}), found {_show(sec['port'])}")


def _baud(sec: dict, where: str, path: str) -> None:
    baud = sec.get("baud")
    if baud is not None and not (_is_int(baud) and baud > 0):
        raise _error(where, f"{path}.baud", f"must be a positive integer (bits per second) or null "
                     f"for the protocol's default, found {_show(baud)}")


def _is_sim(sec: dict, where: str, path: str, real: str) -> bool:
    """True for ``{"type": "sim"}``; a section of real hardware has no type (turntable, projector)."""
    kind = sec.get("type")
    if kind is None:
        return False
    if kind != "sim":
        raise _error(where, f"{path}.type", f"must be 'sim' or absent ({real}), found {_show(kind)}")
    return True


def _check_turntable(sec, where: str) -> None:
    from rangekit.drivers.turntable import TURNTABLE_PROTOCOLS

    path = "devices.turntable"
    sec = _object(sec, where, path)
    if _is_sim(sec, where, path, "a serial turntable is named by 'protocol' and 'port'"):
        return
    known = ", ".join(repr(k) for k in sorted(TURNTABLE_PROTOCOLS))
    if "protocol" not in sec:
        raise _error(where, f"{path}.protocol", f"missing: one of {known}")
    protocol = sec["protocol"]
    if not isinstance(protocol, str) or protocol.strip().lower() not in TURNTABLE_PROTOCOLS:
        raise _error(where, f"{path}.protocol", f"unknown turntable protocol {_show(protocol)}; known: {known}")
    _port(sec, where, path, "serial port or pyserial URL, e.g. '/dev/ttyUSB0' or 'COM3'")
    _baud(sec, where, path)


def _check_projector(sec, where: str) -> None:
    from rangekit.drivers.projector_control import PROJECTOR_PROTOCOLS

    path = "devices.projector"
    sec = _object(sec, where, path)
    if _is_sim(sec, where, path, "a real projector is named by 'display' and 'control'"):
        return
    if "display" in sec and not (_is_int(sec["display"]) and sec["display"] >= 0):
        raise _error(where, f"{path}.display", "must be a non-negative integer (the SDL display index of the "
                     f"projector's monitor, 0 = primary), found {_show(sec['display'])}")
    control = sec.get("control")
    if control is None:
        return
    path = f"{path}.control"
    control = _object(control, where, path)
    known = ", ".join(repr(p) for p in PROJECTOR_PROTOCOLS)
    if "protocol" not in control:
        raise _error(where, f"{path}.protocol", f"missing: one of {known}")
    protocol = control["protocol"]
    if protocol not in PROJECTOR_PROTOCOLS:
        raise _error(where, f"{path}.protocol", f"unknown projector control protocol {_show(protocol)}; known: {known}")
    if protocol == "pjlink":
        _port(control, where, path, "the projector's host name or address, optionally host:port")
        host, sep, tcp = control["port"].partition(":")
        if sep and not (tcp.isdigit() and 0 < int(tcp) < 65536):
            raise _error(where, f"{path}.port", f"must be host or host:port with a TCP port 1..65535, found "
                         f"{_show(control['port'])}")
    else:
        _port(control, where, path, "serial port, e.g. '/dev/ttyUSB1'")
        if "password" in control:
            raise _error(where, f"{path}.password", f"only the 'pjlink' protocol takes a password, not {protocol!r}")
    _baud(control, where, path)
    if "password" in control and not isinstance(control["password"], str):
        raise _error(where, f"{path}.password", f"must be a string, found {_show(control['password'])}")
    timeout = control.get("timeout")
    if timeout is not None and not (isinstance(timeout, (int, float)) and not isinstance(timeout, bool)
                                    and math.isfinite(timeout) and timeout > 0):
        raise _error(where, f"{path}.timeout", f"must be a positive number of seconds, found {_show(timeout)}")


def _check_camera(sec, where: str) -> None:
    from rangekit.drivers.depthai_camera import SOCKETS

    path = "devices.camera"
    sec = _object(sec, where, path)
    if sec.get("type") not in ("depthai", "sim"):
        raise _error(where, f"{path}.type", f"must be 'depthai' or 'sim', found {_show(sec.get('type'))}")
    if sec["type"] == "sim":
        return
    if sec.get("id") is not None and not isinstance(sec["id"], str):
        raise _error(where, f"{path}.id", "must be a string (device id/MXID, name or IP address) or null for the "
                     f"first device found, found {_show(sec['id'])}")
    if sec.get("socket", "CAM_A") not in SOCKETS:
        raise _error(where, f"{path}.socket", f"must be one of {', '.join(SOCKETS)}, found {_show(sec['socket'])}")


def _check_depthai_record(sec, where: str) -> None:
    from rangekit.drivers.depthai_camera import SOCKETS

    path = "devices.depthai"
    sec = _object(sec, where, path)
    if sec.get("device_id") is not None and not isinstance(sec["device_id"], str):
        raise _error(where, f"{path}.device_id", f"must be a string or null, found {_show(sec['device_id'])}")
    sockets = sec.get("sockets", [])
    if not isinstance(sockets, list) or not all(s in SOCKETS for s in sockets):
        raise _error(where, f"{path}.sockets", f"must be a list of {', '.join(SOCKETS)}, found {_show(sockets)}")
    size = sec.get("size")
    if size is not None and not (isinstance(size, list) and len(size) == 2 and all(_is_int(v) and v > 0 for v in size)):
        raise _error(where, f"{path}.size", f"must be [width, height] in pixels, found {_show(size)}")


def validate_devices(devices: dict, *, where: str) -> None:
    """Check a rig file's ``devices`` section without opening anything.

    Checks the allowed fields of each object (``DEVICE_FIELDS``), the turntable and projector-control
    protocols against the drivers' own lists, ports, baud rates, the display index and the depthai
    socket. Every error is a :class:`~rangekit.errors.ConfigError` reading
    ``{where}: devices.turntable.baud: must be a positive integer ..., found '115k'``.
    """
    devices = _object({} if devices is None else devices, where, "devices")
    checks = {"turntable": _check_turntable, "projector": _check_projector, "camera": _check_camera,
              "depthai": _check_depthai_record}
    for key, value in devices.items():
        if value is not None:
            checks[key](value, where)


def validate_capture(capture: dict, *, where: str) -> None:
    """Check a rig file's ``capture`` section: known fields (``CAPTURE_FIELDS``), numbers in range."""
    path = "capture"
    if capture is None:
        return
    if not isinstance(capture, dict):
        raise _error(where, path, f"must be an object ({{...}}), found {_show(capture)}")
    for key, value in capture.items():
        if key not in CAPTURE_FIELDS:
            raise _error(where, f"{path}.{key}", f"unknown field; capture has only {', '.join(CAPTURE_FIELDS)}")
        if key == "bits":
            if not (_is_int(value) and value in (8, 16)):
                raise _error(where, f"{path}.bits", f"must be 8 or 16, found {_show(value)}")
            continue
        lo, hi, unit = CAPTURE_FIELDS[key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if not number or not lo <= value <= hi:
            hint = " (seconds, not milliseconds)" if number and value > hi else ""
            raise _error(where, f"{path}.{key}", f"must be a number of {unit} from {lo:g} to {hi:g}{hint}, found "
                         f"{_show(value)}")


def validate_rig_for_hardware(rig, *, where: str) -> None:
    """Everything :func:`open_rig_devices` and a hardware scan read from ``rig``, checked before any device
    is opened: ``devices``, ``capture``, and that a projector display has a projector calibration."""
    validate_devices(rig.devices, where=where)
    validate_capture(rig.capture, where=where)
    projector = (rig.devices or {}).get("projector") or {}
    if "display" in projector and projector.get("type") != "sim" and rig.projector is None:
        raise _error(where, "devices.projector.display", "a projector display needs the projector's calibration "
                     "(field 'projector' is null)")


@dataclass
class HardwareRig:
    """The opened devices of a rig (the :class:`rangekit.devices.Rig` protocol), plus projector control."""

    camera: object
    projector: object
    turntable: object | None
    projector_control: object | None = None

    def close(self) -> None:
        for dev in (self.camera, self.projector, self.turntable, self.projector_control):
            if dev is not None and hasattr(dev, "close"):
                dev.close()


def _section(devices: dict, key: str) -> dict | None:
    """A validated ``devices`` entry, or None when absent or simulated."""
    sec = devices.get(key)
    return None if sec is None or sec.get("type") == "sim" else sec


def open_rig_devices(rig, *, where: str = "rig file", open_camera: bool = True,
                     open_display: bool = True) -> HardwareRig:
    """Open the turntable, projector (display + control) and camera named in ``rig.devices``.

    The rig is checked first (:func:`validate_rig_for_hardware`), so a bad field is reported before any
    device is opened. Errors name the rig-file field (``devices.turntable.protocol``...) or the device's
    port. Devices opened before a failure are closed again.
    """
    validate_rig_for_hardware(rig, where=where)
    devices = rig.devices or {}
    opened: list = []
    try:
        turntable = None
        sec = _section(devices, "turntable")
        if sec is not None:
            from rangekit.drivers.turntable import make_turntable

            try:
                turntable = make_turntable(sec["protocol"], sec["port"], sec.get("baud"))
            except ConfigError as exc:
                raise ConfigError(f"{where}: devices.turntable.protocol: {exc}") from exc
            opened.append(turntable)
        control = None
        sec = _section(devices, "projector") or {}
        if sec.get("control"):
            from rangekit.drivers.projector_control import make_projector_control

            c = sec["control"]
            try:
                control = make_projector_control(c.get("protocol", ""), c.get("port", ""),
                                                 **{k: v for k, v in c.items() if k not in ("protocol", "port")})
            except ConfigError as exc:
                raise ConfigError(f"{where}: devices.projector.control: {exc}") from exc
            opened.append(control)
        projector = None
        if open_display and rig.projector is not None and "display" in sec:
            from rangekit.drivers.display import PygameProjector

            projector = PygameProjector(rig.projector, display=int(sec["display"]))
            opened.append(projector)
        camera = None
        sec = _section(devices, "camera")
        if open_camera and sec is not None:
            from rangekit.drivers.depthai_camera import DepthaiCamera

            camera = DepthaiCamera(sec.get("id"), socket=sec.get("socket", "CAM_A"),
                                   size=(rig.camera.width, rig.camera.height))
            opened.append(camera)
        return HardwareRig(camera, projector, turntable, control)
    except BaseException:
        for dev in opened:
            try:
                dev.close()
            except Exception:
                pass
        raise
