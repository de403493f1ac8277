"""Real hardware drivers: serial turntables (Horus, FabScan), projector control (ESC/VP21, PJLink),
a full-screen projector display (pygame, optional) and the cameras of :data:`rangekit.drivers.cameras.CAMERA_DRIVERS`.

``open_rig_devices(rig)`` opens what a rig file's ``devices`` section names (every field: docs/rig.md)::

    "devices": {
      "turntable": {"protocol": "horus" | "fabscan", "port": "/dev/ttyUSB0", "baud": 115200, "timeout_s": 2},
      "projector": {"display": 1, "control": {"protocol": "escvp21" | "pjlink", "port": "/dev/ttyUSB1"}},
      "camera": {"type": "depthai", "id": null, "socket": "CAM_A", "search_timeout_s": 3}   # or another driver's
    }

Each opened device that can come back after it went away mid-scan has ``reconnect(timeout_s)``;
acquisition calls it with the entry's ``reconnect_timeout_s`` (:func:`rangekit.rig.checks.reconnect_timeout_s`).

The camera is opened with the rig's ``capture.camera`` controls (:func:`rangekit.rig.camera_controls.
controls_from_capture`), and for coded light (a projector display is opened) auto-exposure is refused
unless ``allow_auto_exposure``.

:func:`rangekit.rig.checks.validate_rig_for_hardware` (``devices`` and ``capture``) runs first and opens
nothing, so a typo in the rig file is reported before any device moves. Any section may instead be ``{"type": "sim"}`` (not
opened here; the simulator provides it).
"""

from __future__ import annotations

from dataclasses import dataclass

from rangekit.errors import ConfigError
from rangekit.drivers.cameras import CAMERA_DRIVERS, camera_driver
from rangekit.rig.checks import DEFAULT_REPLY_S, validate_rig_for_hardware

__all__ = ["HardwareRig", "open_rig_devices", "CAMERA_DRIVERS"]


@dataclass
class HardwareRig:
    """The opened devices of a rig (the :class:`rangekit.rig.devices.RigDevices` protocol), plus projector control."""

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


def open_rig_devices(rig, *, where: str = "rig file", open_camera: bool = True, open_display: bool = True,
                     coded_light: bool | None = None) -> HardwareRig:
    """Open the turntable, projector (display + control) and camera named in ``rig.devices``.

    The camera gets ``rig.capture["camera"]``'s controls and ``devices.camera.search_timeout_s``;
    ``coded_light`` (None: whether a projector display is opened) makes it refuse auto-exposure unless
    the rig file allows it.

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
                turntable = make_turntable(sec["protocol"], sec["port"], sec.get("baud"),
                                           timeout=sec.get("timeout_s", DEFAULT_REPLY_S))
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
            camera = camera_driver(sec["type"]).open_camera(
                sec, rig, where=where, coded_light=projector is not None if coded_light is None else coded_light)
            opened.append(camera)
        return HardwareRig(camera, projector, turntable, control)
    except BaseException:
        for dev in opened:
            try:
                dev.close()
            except Exception:
                pass
        raise
