"""Changes to a rig file made by a program (``rangekit check``'s pattern delay and flush frames, the web app's camera
controls): the JSON read, the named fields of its ``capture`` (or ``devices.camera``) section changed, the result checked as a rig file, then
written atomically. Every other field stays as the user wrote it; a change that would make the file invalid is
refused with the rig file's own one-line error, and the file is left as it was."""

from __future__ import annotations

from pathlib import Path

from rangekit.errors import ConfigError, shown
from rangekit.io import atomic_write_json, read_json
from rangekit.rig.camera_controls import CameraControls, controls_from_capture
from rangekit.rig.rig_file import Rig

__all__ = ["write_camera_controls", "write_capture_fields", "write_camera_section_fields"]


def write_capture_fields(rig_file: str | Path, fields: dict, *, camera: dict | None = None) -> Rig:
    """Set ``capture.<name>`` for each of ``fields`` and ``capture.camera.<name>`` for each of ``camera`` in
    ``rig_file``; returns the rig as written. ConfigError (naming the file and the field) before any write."""
    data = read_json(rig_file, what="rig file")
    if not isinstance(data, dict):
        raise ConfigError(f"{rig_file}: expected a JSON object {{...}}")
    capture = data.setdefault("capture", {})
    if not isinstance(capture, dict):
        raise ConfigError(f"{rig_file}: capture: expected an object {{...}}, found {shown(capture)}")
    capture.update(fields)
    if camera:
        cam = capture.setdefault("camera", {})
        if not isinstance(cam, dict):
            raise ConfigError(f"{rig_file}: capture.camera: expected an object {{...}}, found {shown(cam)}")
        cam.update(camera)
    rig = Rig.from_dict(data, where=str(rig_file))      # the whole file checked before it is written
    controls_from_capture(rig.capture, where=str(rig_file))
    atomic_write_json(rig_file, data)
    return rig


def write_camera_controls(rig_file: str | Path, changes: dict) -> tuple[Rig, CameraControls]:
    """Set the ``capture.camera`` fields of ``changes`` (``exposure_us``, ``iso``, ``white_balance_k``,
    ``focus``, ...: :data:`rangekit.rig.camera_controls.CONTROL_FIELDS`) in ``rig_file``; the rig as written and
    its controls."""
    rig = write_capture_fields(rig_file, {}, camera=changes)
    return rig, controls_from_capture(rig.capture, where=str(rig_file))


def write_camera_section_fields(rig_file: str | Path, fields: dict) -> Rig:
    """Set ``devices.camera.<name>`` for each of ``fields`` in ``rig_file`` (``rangekit check``'s measured
    ``flush_frames``); returns the rig as written. ConfigError (naming the file and the field) before any write,
    e.g. for a field the camera's type does not have."""
    from rangekit.rig.checks import validate_devices

    data = read_json(rig_file, what="rig file")
    camera = data.get("devices", {}).get("camera") if isinstance(data, dict) and isinstance(data.get("devices"),
                                                                                            dict) else None
    if not isinstance(camera, dict):
        raise ConfigError(f"{rig_file}: devices.camera: expected an object {{...}}, found {shown(camera)}")
    camera.update(fields)
    rig = Rig.from_dict(data, where=str(rig_file))
    validate_devices(rig.devices, where=str(rig_file))
    atomic_write_json(rig_file, data)
    return rig
