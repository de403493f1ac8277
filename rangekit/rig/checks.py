"""Checks of a rig file's ``devices`` and ``capture`` sections, without opening anything.

:func:`rangekit.rig.rig_file.load_rig` checks the geometry; :func:`validate_rig_for_hardware` checks what a hardware
scan reads besides (every field: docs/rig.md), so a typo in the rig file is reported before any device
moves. The protocol names and camera sockets the checks accept are constants here, and the drivers in
:mod:`rangekit.drivers` use them. Every error is a :class:`~rangekit.errors.ConfigError` reading
``{where}: devices.turntable.baud: must be a positive integer ..., found '115k'``.
"""

from __future__ import annotations

import math

from rangekit.budget import MAX_IMAGE_SIDE_PX
from rangekit.rig.camera_controls import check_refresh, controls_from_capture
from rangekit.errors import ConfigError

__all__ = ["validate_devices", "validate_capture", "validate_rig_for_hardware", "DEVICE_FIELDS", "CAPTURE_FIELDS",
           "CAPTURE_BITS", "CAMERA_TYPES", "GENICAM_PIXEL_FORMATS", "GENICAM_TRIGGER_ACTIVATIONS", "CAMERA_SECTION_FIELDS",
           "CAMERA_TEMPLATES", "TURNTABLE_PROTOCOLS", "PROJECTOR_PROTOCOLS", "DEPTHAI_SOCKETS", "MAX_SEARCH_S",
           "REFRESH_HZ", "DEFAULT_SEARCH_S", "UVC_FORMATS", "MAX_FLUSH_FRAMES", "DEFAULT_FLUSH_FRAMES",
           "DEFAULT_RECONNECT_S", "DEFAULT_REPLY_S", "reconnect_timeout_s", "CAPTURE_TRIGGERS", "camera_triggered"]

#: Serial turntable protocols (rangekit.drivers.turntable): Horus (Ciclop) and FabScan boards.
TURNTABLE_PROTOCOLS = ("horus", "fabscan")
#: Projector control protocols (rangekit.drivers.projector_control): Epson serial, PJLink over TCP.
PROJECTOR_PROTOCOLS = ("escvp21", "pjlink")
#: depthai camera board sockets (rangekit.drivers.depthai.camera).
DEPTHAI_SOCKETS = ("CAM_A", "CAM_B", "CAM_C", "CAM_D", "CAM_E", "CAM_F", "CAM_G", "CAM_H")
#: The pixel formats a GenICam camera's frames are read in (rangekit.drivers.genicam.frames: mono as is, Bayer made
#: grey, RGB as RGB).
GENICAM_PIXEL_FORMATS = ("Mono8", "Mono10", "Mono12", "Mono16",
                         *(f"Bayer{p}{b}" for p in ("RG", "GR", "GB", "BG") for b in (8, 10, 12, 16)),
                         "RGB8", "BGR8", "RGBa8", "BGRa8")
#: GenICam's ``TriggerActivation`` values (SFNC): the edge or level of a hardware trigger line.
GENICAM_TRIGGER_ACTIVATIONS = ("RisingEdge", "FallingEdge", "AnyEdge", "LevelHigh", "LevelLow")
#: The longest depthai device search accepted (seconds; depthai takes it as a C int of milliseconds), and
#: the search a camera opened from a rig file gets without ``devices.camera.search_timeout_s``.
MAX_SEARCH_S = 600.0
DEFAULT_SEARCH_S = 3.0
#: ``devices.<device>.reconnect_timeout_s`` when absent: seconds a scan waits for a device that went away
#: mid-scan (unplugged, reset, stopped answering) to come back before it ends; long enough for a USB device
#: to enumerate again and an OAK camera to boot. 0: never wait.
DEFAULT_RECONNECT_S = 10.0
#: ``devices.camera.format`` of a "uvc" camera (rangekit.drivers.uvc.camera); ``flush_frames`` (uvc, genicam): the
#: most frames a capture may discard after a pattern change, and a webcam's number when absent (OpenCV's V4L2
#: backend queues 4).
UVC_FORMATS = ("MJPEG", "YUYV")
MAX_FLUSH_FRAMES = 32
DEFAULT_FLUSH_FRAMES = 4
#: ``devices.turntable.timeout_s`` when absent: seconds a turntable board may take to answer a command.
DEFAULT_REPLY_S = 2.0
#: ``devices.projector.refresh_hz``: the projector's refresh rate, Hz (smallest, largest).
REFRESH_HZ = (1.0, 480.0)

#: Allowed fields of each object in a rig file's ``devices`` section, by dotted path.
DEVICE_FIELDS = {
    "devices": ("turntable", "projector", "camera", "depthai"),
    "devices.turntable": ("type", "protocol", "port", "baud", "timeout_s", "reconnect_timeout_s"),
    "devices.projector": ("type", "display", "control", "refresh_hz", "reconnect_timeout_s"),
    "devices.projector.control": ("protocol", "port", "baud", "timeout", "password"),
    "devices.camera": ("type",),   # and the fields of its type: CAMERA_SECTION_FIELDS
    "devices.depthai": ("device_id", "sockets", "size"),  # written by depthai.camera.calibration_to_rig
}
#: The ``capture`` settings: name -> (smallest, largest allowed value, unit). ``bits`` is the camera's
#: ADC bit depth, one of CAPTURE_BITS; a session records it once (rangekit.formats.sessions.session.CaptureSettings)
#: and decodes with full scale 2**bits - 1. ``capture.camera`` (the camera's controls) is checked by
#: :func:`rangekit.rig.camera_controls.controls_from_capture`.
CAPTURE_FIELDS = {
    "pattern_delay_s": (0.0, 10.0, "seconds"),
    "turntable_settle_s": (0.0, 60.0, "seconds"),
    "bits": (8, 16, "bits per pixel"),
}
CAPTURE_BITS = (8, 10, 12, 16)
#: ``capture.trigger``: what starts each exposure. ``"none"`` (the default): the camera runs free, and a scan waits
#: ``capture.pattern_delay_s`` after each pattern before it takes the next frame; ``"projector"``: the camera is
#: triggered by the projector's VSYNC, one trigger for each new pattern, exposing while that pattern is shown, so a
#: scan waits no pattern delay and checks each frame's trigger count (:mod:`rangekit.app.acquire.triggered`).
CAPTURE_TRIGGERS = ("none", "projector")


def camera_triggered(capture: dict | None) -> bool:
    """Whether a rig file's ``capture`` section says the camera is triggered by the projector
    (``capture.trigger`` "projector"); the one reading of that field."""
    return (capture or {}).get("trigger", "none") == "projector"


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


_RECONNECT = "seconds (how long a scan waits for the device to come back)"


def reconnect_timeout_s(devices: dict | None, name: str) -> float:
    """Seconds a scan waits for device ``name`` ("turntable", "projector", "camera") to come back after it went
    away mid-scan: the rig file's ``devices.<name>.reconnect_timeout_s``, else :data:`DEFAULT_RECONNECT_S`."""
    sec = (devices or {}).get(name) or {}
    return float(sec.get("reconnect_timeout_s", DEFAULT_RECONNECT_S)) if isinstance(sec, dict) else DEFAULT_RECONNECT_S


def _check_turntable(sec, where: str) -> None:
    path = "devices.turntable"
    sec = _object(sec, where, path)
    _number_in(sec, "reconnect_timeout_s", 0.0, MAX_SEARCH_S, where, path, _RECONNECT)
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
    _number_in(sec, "timeout_s", 0.01, MAX_SEARCH_S, where, path, "seconds (how long the board may take to answer)")


def _number_in(sec: dict, key: str, lo: float, hi: float, where: str, path: str, unit: str) -> None:
    """``sec[key]``, when present, must be a finite number in lo..hi (``unit`` says what it is)."""
    value = sec.get(key)
    if key in sec and not (isinstance(value, (int, float)) and not isinstance(value, bool)
                           and math.isfinite(value) and lo <= value <= hi):
        raise _error(where, f"{path}.{key}", f"must be a number of {unit} from {lo:g} to {hi:g}, found {_show(value)}")


def _check_projector(sec, where: str) -> None:
    path = "devices.projector"
    sec = _object(sec, where, path)
    _number_in(sec, "reconnect_timeout_s", 0.0, MAX_SEARCH_S, where, path, _RECONNECT)
    _number_in(sec, "refresh_hz", *REFRESH_HZ, where, path, "hertz (the projector's refresh rate, e.g. 60)")
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


#: The fields of ``devices.camera`` by its ``type`` (besides ``type``), one entry per camera driver
#: (rangekit.drivers.CAMERA_DRIVERS has the same keys; tests/rig/test_rig_file.py checks they agree). Each type's
#: checker is in :data:`_CAMERA_CHECKS`, its section in ``rangekit rig init --camera TYPE`` in
#: :data:`CAMERA_TEMPLATES`.
CAMERA_SECTION_FIELDS = {
    "depthai": ("id", "socket", "search_timeout_s", "reconnect_timeout_s"),
    "realsense": ("serial", "bag", "infrared", "search_timeout_s", "reconnect_timeout_s"),
    "uvc": ("device", "format", "flush_frames", "reconnect_timeout_s"),
    "genicam": ("producer", "serial", "user_id", "pixel_format", "trigger_source", "trigger_activation", "flush_frames",
                "search_timeout_s", "reconnect_timeout_s"),
}
#: ``devices.camera.type``: the simulator's camera, or one of the camera drivers.
CAMERA_TYPES = ("sim", *CAMERA_SECTION_FIELDS)
#: Each driver's ``devices.camera`` section as ``rangekit rig init --camera TYPE`` writes it.
CAMERA_TEMPLATES = {
    "depthai": {"type": "depthai", "id": None, "socket": "CAM_A", "search_timeout_s": DEFAULT_SEARCH_S},
    "realsense": {"type": "realsense", "serial": None, "bag": None, "infrared": 1,
                  "search_timeout_s": DEFAULT_SEARCH_S},
    "uvc": {"type": "uvc", "device": "/dev/video0", "format": "MJPEG", "flush_frames": DEFAULT_FLUSH_FRAMES},
    "genicam": {"type": "genicam", "producer": None, "serial": None, "user_id": None, "pixel_format": "Mono8",
                "trigger_source": None, "trigger_activation": "RisingEdge", "flush_frames": 2,
                "search_timeout_s": DEFAULT_SEARCH_S},
}


def _check_camera(sec, where: str) -> None:
    path = "devices.camera"
    if not isinstance(sec, dict):
        raise _error(where, path, f"must be an object ({{...}}), found {_show(sec)}")
    kind = sec.get("type")
    if kind not in CAMERA_TYPES:
        raise _error(where, f"{path}.type", f"must be one of {', '.join(repr(t) for t in CAMERA_TYPES)}, "
                                            f"found {_show(kind)}")
    allowed = ("type", *CAMERA_SECTION_FIELDS.get(kind, ()))
    unknown = [k for k in sec if k not in allowed]
    if unknown:
        raise _error(where, f"{path}.{unknown[0]}", f"unknown field; a {kind!r} camera has only {', '.join(allowed)}")
    if kind != "sim":
        _number_in(sec, "reconnect_timeout_s", 0.0, MAX_SEARCH_S, where, path, _RECONNECT)   # every driver's
        _CAMERA_CHECKS[kind](sec, where, path)


def _check_depthai_camera(sec: dict, where: str, path: str) -> None:
    if sec.get("id") is not None and not isinstance(sec["id"], str):
        raise _error(where, f"{path}.id", "must be a string (device id/MXID, name or IP address) or null for the "
                     f"first device found, found {_show(sec['id'])}")
    if sec.get("socket", "CAM_A") not in DEPTHAI_SOCKETS:
        raise _error(where, f"{path}.socket", f"must be one of {', '.join(DEPTHAI_SOCKETS)}, found {_show(sec['socket'])}")
    _number_in(sec, "search_timeout_s", 0.0, MAX_SEARCH_S, where, path, "seconds (how long to look for the device)")
    _number_in(sec, "reconnect_timeout_s", 0.0, MAX_SEARCH_S, where, path, _RECONNECT)


def _check_realsense_camera(sec: dict, where: str, path: str) -> None:
    for key, what in (("serial", "the camera's serial number (rangekit devices lists it) or null for the first found"),
                      ("bag", "the path of a recording (.bag or .db3) to play instead of a camera, or null")):
        if sec.get(key) is not None and not (isinstance(sec[key], str) and sec[key]):
            raise _error(where, f"{path}.{key}", f"must be a string ({what}), found {_show(sec[key])}")
    if sec.get("bag") is not None and not sec["bag"].lower().endswith((".bag", ".db3")):
        raise _error(where, f"{path}.bag", f"must be a RealSense recording ending with .bag or .db3, found "
                                           f"{_show(sec['bag'])}")
    if sec.get("infrared", 1) not in (1, 2) or isinstance(sec.get("infrared"), bool):
        raise _error(where, f"{path}.infrared", f"must be 1 (the left imager, the depth's frame) or 2, found "
                                                f"{_show(sec['infrared'])}")
    _number_in(sec, "search_timeout_s", 0.0, MAX_SEARCH_S, where, path, "seconds (how long to look for the device)")


def _check_uvc_camera(sec: dict, where: str, path: str) -> None:
    device = sec.get("device", 0)
    if not ((_is_int(device) and device >= 0) or (isinstance(device, str) and device.strip())):
        raise _error(where, f"{path}.device", "must be a device path ('/dev/video0', a '/dev/v4l/by-id/...' link) or "
                     f"an index >= 0 (0 = /dev/video0), found {_show(device)}")
    if sec.get("format", "MJPEG") not in UVC_FORMATS:
        raise _error(where, f"{path}.format", f"must be one of {', '.join(UVC_FORMATS)}, found {_show(sec['format'])}")
    flush = sec.get("flush_frames", 0)
    if not (_is_int(flush) and 0 <= flush <= MAX_FLUSH_FRAMES):
        raise _error(where, f"{path}.flush_frames", f"must be a whole number of frames 0..{MAX_FLUSH_FRAMES} (the "
                     f"stale frames dropped after a pattern change; rangekit check measures it), found {_show(flush)}")


def _check_genicam_camera(sec: dict, where: str, path: str) -> None:
    for key, what in (("producer", "the path of the camera maker's GenTL producer (.cti), or null for "
                                   "GENICAM_GENTL64_PATH"),
                      ("serial", "the camera's serial number, or null"), ("user_id", "the camera's user id, or null"),
                      ("trigger_source", "'Software', a line such as 'Line1', or null for a free-running camera")):
        if sec.get(key) is not None and not (isinstance(sec[key], str) and sec[key].strip()):
            raise _error(where, f"{path}.{key}", f"must be a non-empty string ({what}), found {_show(sec[key])}")
    if sec.get("pixel_format", "Mono8") not in GENICAM_PIXEL_FORMATS:
        raise _error(where, f"{path}.pixel_format", f"must be one of {', '.join(GENICAM_PIXEL_FORMATS)}, found "
                     f"{_show(sec['pixel_format'])}")
    if sec.get("trigger_activation", "RisingEdge") not in GENICAM_TRIGGER_ACTIVATIONS:
        raise _error(where, f"{path}.trigger_activation", f"must be one of {', '.join(GENICAM_TRIGGER_ACTIVATIONS)}, "
                     f"found {_show(sec['trigger_activation'])}")
    flush = sec.get("flush_frames", 2)
    if not (_is_int(flush) and 0 <= flush <= MAX_FLUSH_FRAMES):
        raise _error(where, f"{path}.flush_frames", f"must be an integer 0..{MAX_FLUSH_FRAMES} (frames dropped after "
                     f"each pattern change), found {_show(flush)}")
    _number_in(sec, "search_timeout_s", 0.0, MAX_SEARCH_S, where, path, "seconds (how long to look for the device)")
    _number_in(sec, "reconnect_timeout_s", 0.0, MAX_SEARCH_S, where, path, _RECONNECT)


#: Each camera type's checker of its section's values (the fields are checked against CAMERA_SECTION_FIELDS first).
_CAMERA_CHECKS = {
    "depthai": _check_depthai_camera,
    "realsense": _check_realsense_camera,
    "uvc": _check_uvc_camera,
    "genicam": _check_genicam_camera,
}


def _check_depthai_record(sec, where: str) -> None:
    path = "devices.depthai"
    sec = _object(sec, where, path)
    if sec.get("device_id") is not None and not isinstance(sec["device_id"], str):
        raise _error(where, f"{path}.device_id", f"must be a string or null, found {_show(sec['device_id'])}")
    sockets = sec.get("sockets", [])
    if not isinstance(sockets, list) or not all(s in DEPTHAI_SOCKETS for s in sockets):
        raise _error(where, f"{path}.sockets", f"must be a list of {', '.join(DEPTHAI_SOCKETS)}, found {_show(sockets)}")
    size = sec.get("size")
    if size is not None and not (isinstance(size, list) and len(size) == 2
                                 and all(_is_int(v) and 0 < v <= MAX_IMAGE_SIDE_PX for v in size)):
        raise _error(where, f"{path}.size", f"must be [width, height] in pixels, each 1..{MAX_IMAGE_SIDE_PX}, found "
                     f"{_show(size)}")


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
    """Check a rig file's ``capture`` section: known fields (``CAPTURE_FIELDS``, ``camera`` and ``trigger``, one of
    :data:`CAPTURE_TRIGGERS`), numbers in range."""
    path = "capture"
    if capture is None:
        return
    if not isinstance(capture, dict):
        raise _error(where, path, f"must be an object ({{...}}), found {_show(capture)}")
    controls_from_capture(capture, where=where)
    for key, value in capture.items():
        if key == "camera":
            continue
        if key == "trigger":
            if value not in CAPTURE_TRIGGERS:
                raise _error(where, f"{path}.trigger", f"must be {' or '.join(repr(t) for t in CAPTURE_TRIGGERS)} "
                             f"(what starts each exposure), found {_show(value)}")
            continue
        if key not in CAPTURE_FIELDS:
            raise _error(where, f"{path}.{key}", f"unknown field; capture has only camera, trigger, "
                         f"{', '.join(CAPTURE_FIELDS)}")
        if key == "bits":
            if not (_is_int(value) and value in CAPTURE_BITS):
                raise _error(where, f"{path}.bits", f"must be {', '.join(map(str, CAPTURE_BITS[:-1]))} or "
                             f"{CAPTURE_BITS[-1]} (the camera's bit depth), found {_show(value)}")
            continue
        lo, hi, unit = CAPTURE_FIELDS[key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        if not number or not lo <= value <= hi:
            hint = " (seconds, not milliseconds)" if number and value > hi else ""
            raise _error(where, f"{path}.{key}", f"must be a number of {unit} from {lo:g} to {hi:g}{hint}, found "
                         f"{_show(value)}")


def validate_rig_for_hardware(rig, *, where: str) -> None:
    """Everything :func:`open_rig_devices` and a hardware scan read from ``rig``, checked before any device
    is opened: ``devices``, ``capture``, that a manual exposure is a whole number of the projector's
    refresh periods (``devices.projector.refresh_hz``, :func:`rangekit.rig.camera_controls.check_refresh`) and
    that a projector display has a projector calibration."""
    validate_devices(rig.devices, where=where)
    validate_capture(rig.capture, where=where)
    projector = (rig.devices or {}).get("projector") or {}
    check_refresh(controls_from_capture(rig.capture, where=where), projector.get("refresh_hz"), where=where)
    if "display" in projector and projector.get("type") != "sim" and rig.projector is None:
        raise _error(where, "devices.projector.display", "a projector display needs the projector's calibration "
                     "(field 'projector' is null)")
