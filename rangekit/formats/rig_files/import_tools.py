"""Calibration files that structured-light tools write (``rangekit rig import``), told apart by their keys.

Each tool's file is an OpenCV FileStorage with its own key names, units and extrinsic convention, taken
from the tool's source (:data:`TOOL_CALIBRATIONS`). Every one has ``cv2.stereoCalibrate``'s convention,
the first camera's points mapped into the second device's frame: ``X_second = R X_cam + T``.

- **SLStudio** (github jakobwilm/slstudio, ``src/calibrator/CalibrationData.cpp``): ``Kc``, ``kc`` (camera;
  radial k1 only in practice), ``Kp``, ``kp`` (projector), ``Rp``, ``Tp`` with ``X_proj = Rp X_cam + Tp`` in
  millimetres, the camera size ``frameWidth`` x ``frameHeight``, the projector's ``screenResX`` x
  ``screenResY`` (the screen the codecs address, which the projector matrix is in).
- **kamino410 procam-calibration** ``calibration_result.xml`` (github kamino410/procam-calibration,
  ``calibrate.py``: ``cv2.stereoCalibrate(objps, cam_corners, proj_corners, ...)``, then
  ``fs.write(...)``): ``cam_int``, ``cam_dist``, ``proj_int``, ``proj_dist``, the rotation under
  ``roration`` (sic, in the version that wrote its ``sample_data/calibration_result.xml``) or ``rotation``
  (a later version), ``translation``; also ``img_shape`` (the camera image's numpy shape: [rows, cols],
  height first) and ``rms``. ``translation`` is in the unit of the square size given to ``calibrate.py``
  (its README: "mm/cm/m"; its sample's 288 mm baseline is millimetres): read as millimetres unless
  ``unit`` says otherwise. The projector's size is an argument of ``calibrate.py``, not in the file:
  ``projector_size`` (``--projector-size``) is required.
- **Moreno & Taubin's scan3d-capture** ``calibration.yml`` ("Simple, Accurate, and Robust
  Projector-Camera Calibration", 3DIMPVT 2012; its ``CalibrationData::save_calibration_yml`` and
  ``Application::calibrate``, read in the copy github mehrab2603/scan3d-capture, ``src/CalibrationData.cpp``
  and ``src/Application.cpp``; the same keys in the older copies in the code index): ``cam_K``, ``cam_kc``
  (5 coefficients), ``proj_K``, ``proj_kc``, ``R``, ``T``, ``cam_error``, ``proj_error``,
  ``stereo_error`` (some versions add ``E``, ``F``; an early one writes ``b``, ``m`` instead of the
  per-device errors); ``stereo_error`` tells it apart from a plain OpenCV file with the same matrix
  keys. ``T`` is in the unit of the board's corner spacing typed into the program (``main/corners_width``,
  default 21.08: millimetres; the mehrab2603 version's JSON export divides ``T`` by 1000 for metres): read
  as millimetres. Neither image size is in the file (the camera's comes from the images, the projector's
  from ``projector_info.txt``, 1024 x 768 when absent): ``size`` (``--size``) and ``projector_size``
  (``--projector-size``) are required.
- **OpenCV's structured-light point-cloud sample** (github opencv/opencv_contrib,
  ``modules/structured_light/samples/pointcloud.cpp``, also ``test/test_plane.cpp``; the test data
  ``testdata/cv/structured_light/data/calibrationParameters.yml``): two cameras and no projector:
  ``cam1_intrinsics``, ``cam1_distorsion`` (sic; ``cam1_distortion`` is read too), ``cam2_intrinsics``,
  ``cam2_distorsion``, ``R``, ``T`` (``stereoRectify(cam1..., cam2..., R, T)``: ``X_cam2 = R X_cam1 + T``),
  in millimetres (``test_plane.cpp``: "from mm (unit of calibration) to m"); the test data adds
  ``cam1_size``, ``cam2_size`` ([width, height], a ``cv::Size``) and ``stereo_error``. The sample itself
  takes one image size for both cameras from the first white image: without ``cam1_size``, ``size``
  (``--size``) is required; without ``cam2_size``, the second camera has the first one's size.

The unit each tool's translation is read in is reported (``report``), and ``unit`` (``--unit``) overrides it;
a baseline outside :data:`rangekit.rig.plausibility.BASELINE` is refused or warned of, naming the unit its
numbers look like. The rig file's world is the first camera's frame and its turntable is unknown, as for
any imported calibration.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.errors import ConfigError, shown as found_value
from rangekit.formats.rig_files.procam import procam_rig
from rangekit.rig.plausibility import UNIT_NAMES, UNIT_SCALES

__all__ = ["SizeKeys", "ToolCalibration", "TOOL_CALIBRATIONS", "tool_of", "tool_rig"]

_FIELDS = {"camera_K": "camera matrix", "camera_dist": "camera distortion", "projector_K": "projector matrix",
           "projector_dist": "projector distortion", "R": "rotation", "T": "translation"}
#: The fixes a baseline check names, for a tool's file read in the wrong unit.
_UNIT_FIXES = {u: f"use --unit {u}" for u in UNIT_SCALES}


@dataclass(frozen=True)
class SizeKeys:
    """Where a file keeps an image size: two keys (width, height), or one key holding both numbers in
    ``order`` "wh" ([width, height], a ``cv::Size``) or "hw" ([rows, cols], a numpy shape)."""

    keys: tuple[str, ...]
    order: str = "wh"


@dataclass(frozen=True)
class ToolCalibration:
    """Where one tool keeps each value of a two-device calibration (module doc: what each tool writes)."""

    name: str                          # for messages: "SLStudio's calibration.xml"
    signature: tuple[str, ...]         # keys that, all present, tell the tool's file apart
    keys: dict                         # camera_K, camera_dist, projector_K, projector_dist, R, T -> the file's
                                       # key(s), the first present read (projector_*: the second camera's)
    unit: str                          # the unit of T the tool writes ("mm"), a key of UNIT_SCALES
    unit_source: str                   # why (for the report)
    camera_size: SizeKeys | None       # None: not in the file (``size`` is required)
    second_size: SizeKeys | None       # the projector's (None: ``projector_size``) or the second camera's
    second: str = "projector"          # "projector", or "camera" for a two-camera file
    #: Where the tool's own triangulation leaves the projector's lens distortion out although its file holds
    #: one: the source line that says so. Its clouds (and a user's comparison with them) are then those of
    #: the projector without it, and the import follows the tool unless told to keep it.
    drops_projector_distortion: str | None = None


TOOL_CALIBRATIONS = (
    ToolCalibration("SLStudio's calibration.xml", ("Kc",),
                    {"camera_K": ("Kc",), "camera_dist": ("kc",), "projector_K": ("Kp",), "projector_dist": ("kp",),
                     "R": ("Rp",), "T": ("Tp",)}, "mm", "SLStudio's calibration is in millimetres",
                    SizeKeys(("frameWidth", "frameHeight")), SizeKeys(("screenResX", "screenResY")),
                    drops_projector_distortion="SLStudio's Triangulator.cpp builds each column's plane from Kp, Rp, "
                                               "Tp alone"),
    ToolCalibration("kamino410 procam-calibration's calibration_result.xml", ("cam_int",),
                    {"camera_K": ("cam_int",), "camera_dist": ("cam_dist",), "projector_K": ("proj_int",),
                     "projector_dist": ("proj_dist",), "R": ("roration", "rotation"), "T": ("translation",)},
                    "mm", "the unit of the square size given to calibrate.py, millimetres in its sample",
                    SizeKeys(("img_shape",), "hw"), None),
    ToolCalibration("Moreno-Taubin scan3d-capture's calibration.yml", ("cam_K", "stereo_error"),
                    {"camera_K": ("cam_K",), "camera_dist": ("cam_kc",), "projector_K": ("proj_K",),
                     "projector_dist": ("proj_kc",), "R": ("R",), "T": ("T",)},
                    "mm", "the unit of the board's corner size typed into scan3d-capture, millimetres by default",
                    None, None),
    ToolCalibration("OpenCV structured_light sample's calibration", ("cam1_intrinsics",),
                    {"camera_K": ("cam1_intrinsics",), "camera_dist": ("cam1_distorsion", "cam1_distortion"),
                     "projector_K": ("cam2_intrinsics",), "projector_dist": ("cam2_distorsion", "cam2_distortion"),
                     "R": ("R",), "T": ("T",)},
                    "mm", "the sample's calibration is in millimetres, says opencv_contrib's test_plane.cpp",
                    SizeKeys(("cam1_size",)), SizeKeys(("cam2_size",)), second="camera"),
)


def tool_of(values: dict) -> ToolCalibration | None:
    """The tool whose ``signature`` keys are all among ``values`` (a FileStorage's keys), or None; its other
    keys are then required by name (:func:`tool_rig`)."""
    for tool in TOOL_CALIBRATIONS:
        if all(k in values for k in tool.signature):
            return tool
    return None


def tool_rig(tool: ToolCalibration, values: dict, path: Path, *, size: tuple[int, int] | None = None,
             projector_size: tuple[int, int] | None = None, unit: str | None = None,
             keep_projector_distortion: bool = False, report: Callable[[str], None] | None = None) -> dict:
    """The rig file of a tool's calibration (checked by :func:`.procam.procam_rig`). ``size`` /
    ``projector_size``: (width, height) pixels where the file has none; ``unit``: the unit of the file's
    translation (default the tool's, ``tool.unit``); ``report``: told the tool and the unit read.
    A tool whose triangulation leaves the projector's distortion out (``drops_projector_distortion``) gets
    a projector without it, as the tool reconstructs, unless ``keep_projector_distortion``."""
    path = Path(path)
    keys = {field: _matrix(tool, field, values, path) for field in tool.keys}   # every one, before any check
    if unit is not None and unit not in UNIT_SCALES:
        raise ConfigError(f"{path}: unit: expected one of {', '.join(UNIT_SCALES)}, found {unit!r}")
    read_as = tool.unit if unit is None else unit
    if tool.second == "camera" and projector_size is not None:
        raise ConfigError(f"{path}: --projector-size: expected none ({tool.name} has two cameras and no "
                          f"projector), found {projector_size[0]}x{projector_size[1]}")
    cam_size = _size(values, tool.camera_size, path, "camera image" if tool.second == "projector" else "first "
                     "camera's image", size, "--size")
    if tool.second == "camera":
        second_size = _size(values, tool.second_size, path, "second camera's image", cam_size, None)
    else:
        second_size = _size(values, tool.second_size, path, "projector", projector_size, "--projector-size")
    if report is not None:
        why = "as given" if unit is not None else f"{tool.unit_source}; --unit m, cm or mm if it is in another"
        report(f"{path}: read as {tool.name}; {keys['T'][0]} in {UNIT_NAMES[read_as]} ({why})")
    dist_key, dist = keys["projector_dist"]
    if tool.drops_projector_distortion and not keep_projector_distortion and np.any(np.asarray(dist, float) != 0):
        keys["projector_dist"] = (dist_key, np.zeros_like(np.asarray(dist, dtype=np.float64)))
        if report is not None:
            report(f"{path}: {dist_key} left out, as the tool reconstructs ({tool.drops_projector_distortion}); "
                   f"--keep-projector-distortion keeps it")
    return procam_rig(path, keys, read_as, cam_size, second_size, UNIT_SCALES, _UNIT_FIXES, second=tool.second)


def _matrix(tool: ToolCalibration, field: str, values: dict, path: Path):
    """(key, value) of a tool's ``field``: the first of its keys the file has; ConfigError when none."""
    for key in tool.keys[field]:
        if key in values:
            if values[key] is None:
                raise ConfigError(f"{path}: {key}: expected a matrix (the {_label(tool, field)} of {tool.name}), "
                                  f"found an empty value")
            return key, values[key]
    raise ConfigError(f"{path}: {'/'.join(tool.keys[field])}: expected a matrix (the {_label(tool, field)} of "
                      f"{tool.name}), found no such key; the file has {', '.join(values)}")


def _label(tool: ToolCalibration, field: str) -> str:
    label = _FIELDS[field]
    return label.replace("projector", "second camera's") if tool.second == "camera" else label


def _size(values: dict, where: SizeKeys | None, path: Path, label: str, given, option: str | None):
    """(width, height) pixels: from the file's ``where`` keys, else ``given`` (the option's value, or the
    first camera's size for a second camera), else ConfigError naming ``option``."""
    present = [] if where is None else [values.get(k) for k in where.keys]
    if not any(v is not None for v in present):
        if given is not None:
            return tuple(given)
        keys = "none" if where is None else f"no {'/'.join(where.keys)}"
        raise ConfigError(f"{path}: expected the {label} size (width x height in pixels), found {keys} in the file; "
                          f"give it with {option} WxH")
    shown = "/".join(where.keys)
    try:
        numbers = [float(np.asarray(v, dtype=np.float64).ravel()[0]) if np.asarray(v).size == 1 else np.nan
                   for v in present] if len(where.keys) == 2 else np.asarray(present[0], np.float64).ravel().tolist()
    except (TypeError, ValueError):
        numbers = [np.nan]
    if len(numbers) == 2 and where.order == "hw":
        numbers = numbers[::-1]
    if not (len(numbers) == 2 and all(np.isfinite(x) and x == round(x) and x > 0 for x in numbers)):
        found = [None if v is None else np.asarray(v).tolist() for v in present]
        expected = ("a width and a height in pixels" if len(where.keys) == 2 else
                    "[height, width] in pixels" if where.order == "hw" else "[width, height] in pixels")
        raise ConfigError(f"{path}: {shown}: expected {expected}, found {found_value(found if len(found) > 1 else found[0])}")
    return int(numbers[0]), int(numbers[1])
