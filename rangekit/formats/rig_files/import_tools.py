"""Calibration files that structured-light tools write (``rangekit rig import``), told apart by their keys.

Each tool's file is an OpenCV FileStorage with its own key names, units and extrinsic convention, taken
from the tool's source (:data:`TOOL_CALIBRATIONS`):

- **SLStudio** (github jakobwilm/slstudio, ``src/calibrator/CalibrationData.cpp``): ``Kc``, ``kc`` (camera;
  radial k1 only in practice), ``Kp``, ``kp`` (projector), ``Rp``, ``Tp`` with ``X_proj = Rp X_cam + Tp`` in
  millimetres, the camera size ``frameWidth`` x ``frameHeight``, the projector's ``screenResX`` x
  ``screenResY`` (the screen the codecs address, which the projector matrix is in).

The rig file's world is the camera's frame and its turntable is unknown, as for any imported calibration.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError
from rangekit.formats.rig_files.procam import procam_rig
from rangekit.rig.plausibility import UNIT_SCALES

__all__ = ["ToolCalibration", "TOOL_CALIBRATIONS", "tool_of", "tool_rig"]


@dataclass(frozen=True)
class ToolCalibration:
    """Where one tool keeps each value of a camera-projector calibration."""

    name: str                          # for messages: "SLStudio calibration.xml"
    keys: dict                         # camera_K, camera_dist, projector_K, projector_dist, R, T -> the file's key
    unit: str                          # the unit of T ("mm", "m")
    camera_size: tuple[str, str]       # keys of the camera image's width and height
    projector_size: tuple[str, str]    # keys of the projector's width and height


TOOL_CALIBRATIONS = (
    ToolCalibration("SLStudio calibration.xml",
                    {"camera_K": "Kc", "camera_dist": "kc", "projector_K": "Kp", "projector_dist": "kp", "R": "Rp",
                     "T": "Tp"}, "mm", ("frameWidth", "frameHeight"), ("screenResX", "screenResY")),
)


def tool_of(values: dict) -> ToolCalibration | None:
    """The tool whose matrices' keys (``keys``) are all among ``values`` (a FileStorage's keys), or None; its
    other keys are then required by name."""
    for tool in TOOL_CALIBRATIONS:
        if all(k in values for k in tool.keys.values()):
            return tool
    return None


def _size(values: dict, keys: tuple[str, str], path: Path) -> tuple[int, int]:
    v = [values.get(k) for k in keys]
    w, h = (float(np.asarray(x).ravel()[0]) if x is not None and np.asarray(x).size == 1 else np.nan for x in v)
    if not (np.isfinite(w) and np.isfinite(h) and w == round(w) and h == round(h) and w > 0 and h > 0):
        raise ConfigError(f"{path}: {keys[0]}/{keys[1]}: expected a width and a height in pixels, found "
                          f"{[None if x is None else np.asarray(x).tolist() for x in v]}")
    return int(w), int(h)


def tool_rig(tool: ToolCalibration, values: dict, path: Path) -> dict:
    """The rig file of a tool's calibration (checked as an OpenCV stereo calibration is)."""
    keys = {field: (key, values[key]) for field, key in tool.keys.items()}
    for field, (key, value) in keys.items():
        if value is None:
            raise ConfigError(f"{path}: {key}: expected a matrix ({tool.name}'s {field}), found an empty value")
    units = {tool.unit: UNIT_SCALES[tool.unit]}
    return procam_rig(path, keys, tool.unit, _size(values, tool.camera_size, path),
                      _size(values, tool.projector_size, path), units, {})
