"""``rangekit rig import``: a rig file from a calibration the user already has.

Four kinds of source, told apart by their content (:func:`import_rig`):

- **OpenCV stereo calibration** (YAML or XML written by ``cv2.FileStorage``, read with it): the camera is
  the first device, the projector the second (``cv2.stereoCalibrate``'s convention: ``R``, ``T`` map the
  camera's frame to the projector's, ``X_proj = R X_cam + T``). Keys read, first found wins:

  ==================  ==========================================================================
  camera matrix       ``K1``, ``M1``, ``cameraMatrix1``, ``camera_matrix``, ``cameraMatrix``, ``cam_K``
  camera distortion   ``D1``, ``distCoeffs1``, ``dist_coeffs1``, ``distortion_coefficients``,
                      ``distCoeffs``, ``cam_kc``
  projector matrix    ``K2``, ``M2``, ``cameraMatrix2``, ``projector_matrix``, ``proj_K``
  projector dist.     ``D2``, ``distCoeffs2``, ``dist_coeffs2``, ``projector_distortion``, ``proj_kc``
  rotation            ``R`` (3x3) or a Rodrigues vector (3 numbers); translation ``T`` (3)
  camera size         ``imageSize``, ``image_size``, ``cam_size`` ([w, h]); or ``image_width`` and
                      ``image_height``; else ``--size``
  projector size      ``projectorSize``, ``projector_size``, ``proj_size`` ([w, h]); or
                      ``projector_width`` and ``projector_height``; else ``--projector-size``
  ==================  ==========================================================================

  ``T`` is in metres unless ``unit`` says otherwise (``--unit mm`` or ``cm``); a baseline ``|T|`` outside
  :data:`rangekit.rig.plausibility.BASELINE` is refused (zero, below 1 mm or above 10 m: a file in millimetres
  read as metres, or the other way round) or warned of. World = the camera's frame; the turntable is
  unknown (``T_world_table`` null: ``rangekit calibrate`` measures it).
- **Structured-light tools' calibration files** (SLStudio's ``calibration.xml``, kamino410 procam-calibration's
  ``calibration_result.xml``, Moreno-Taubin scan3d-capture's ``calibration.yml``, OpenCV's structured-light
  sample's two-camera calibration), recognised by their keys (:mod:`.import_tools`: each tool's keys, units
  and extrinsic convention); ``unit`` overrides the tool's unit.
- **depthai EEPROM calibration** JSON (``CalibrationHandler.eepromToJson()``, :mod:`.rig_import_json`).
- **Horus** ``calibration.json`` (Ciclop scanner, :mod:`.rig_import_json`).
- **RoomAlive Toolkit**'s ``ProjectorCameraEnsemble`` XML (a Kinect v2's colour and depth cameras and a projector,
  :mod:`.roomalive`), told by its root element.

Every problem raises :class:`ConfigError` naming the file, the key, the expected and the found value.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.regular_files import read_regular_file
from rangekit.errors import ConfigError, shown as found_value
from rangekit.formats.rig_files.procam import procam_rig
from rangekit.rig.plausibility import UNIT_SCALES
from rangekit.rig.rig_file import Rig

__all__ = ["import_rig", "IMPORT_SUFFIXES", "OPENCV_KEYS", "read_opencv"]

#: The extensions ``rig import`` reads: OpenCV's FileStorage (YAML, XML, JSON) and the vendors' JSON.
IMPORT_SUFFIXES = (".yaml", ".yml", ".xml", ".json")

#: Keys of an OpenCV stereo calibration, each field's names in the order they are looked up.
OPENCV_KEYS = {
    "camera_K": ("K1", "M1", "cameraMatrix1", "camera_matrix", "cameraMatrix", "cam_K"),
    "camera_dist": ("D1", "distCoeffs1", "dist_coeffs1", "distortion_coefficients", "distCoeffs", "cam_kc"),
    "projector_K": ("K2", "M2", "cameraMatrix2", "projector_matrix", "proj_K"),
    "projector_dist": ("D2", "distCoeffs2", "dist_coeffs2", "projector_distortion", "proj_kc"),
    "R": ("R",),
    "T": ("T",),
    "camera_size": ("imageSize", "image_size", "cam_size"),
    "projector_size": ("projectorSize", "projector_size", "proj_size"),
}
#: The units an OpenCV file's ``T`` is guessed in when its baseline is out of range, metres per unit, and how
#: to ask for each (``--unit`` reads any of :data:`UNIT_SCALES`).
UNITS = {u: UNIT_SCALES[u] for u in ("m", "mm")}
_UNIT_FIXES = {"mm": "use --unit mm", "m": "use --unit m (the default)"}


def import_rig(path: str | Path, *, size: tuple[int, int] | None = None,
               projector_size: tuple[int, int] | None = None, unit: str | None = None,
               keep_projector_distortion: bool = False, report: Callable[[str], None] | None = None) -> dict:
    """The rig file (plain JSON types, validated by :meth:`Rig.from_dict`) of the calibration in ``path``.
    ``size`` / ``projector_size``: (width, height) pixels where the file has none (Horus never has one);
    ``unit``: the translation's unit, "m", "cm" or "mm" (default: metres for an OpenCV file, the tool's unit
    for a tool's file; depthai's centimetres and Horus's millimetres are known); ``report``: told which
    tool's file was read and the unit of its translation. ``keep_projector_distortion``: keep the projector's
    distortion of a tool whose own triangulation leaves it out (SLStudio's), which the import drops by default
    (:func:`.import_tools.tool_rig`)."""
    from rangekit.formats.rig_files.import_json import depthai_rig, horus_rig
    from rangekit.formats.rig_files.roomalive import is_roomalive, roomalive_rig

    path = Path(path)
    if path.suffix.lower() not in IMPORT_SUFFIXES:
        raise ConfigError(f"{path}: expected a calibration file ({', '.join(IMPORT_SUFFIXES)}), found "
                          f"{repr(path.suffix) if path.suffix else 'no extension'}")
    if not path.is_file():
        raise ConfigError(f"{path}: expected a calibration file, found {'a folder' if path.is_dir() else 'no file'}")
    data = None
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(read_regular_file(path, what="a calibration file").decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{path}: expected JSON, found a file that does not parse ({exc})") from None
        except RecursionError:
            raise ConfigError(f"{path}: expected a calibration JSON, found arrays or objects nested too deeply to "
                              f"read") from None
    if path.suffix.lower() == ".xml" and is_roomalive(path):
        rig = roomalive_rig(path, report=report)
    elif isinstance(data, dict) and "cameraData" in data:
        rig = depthai_rig(data, str(path))
    elif isinstance(data, dict) and ("calibration_settings" in data or "camera_matrix" in data):
        rig = horus_rig(data, str(path), size=size)
    else:
        from rangekit.formats.rig_files.import_tools import tool_of, tool_rig

        values = read_opencv(path)
        tool = tool_of(values)
        rig = (opencv_rig(path, size=size, projector_size=projector_size, unit=unit or "m", values=values)
               if tool is None else tool_rig(tool, values, path, size=size, projector_size=projector_size,
                                             unit=unit, keep_projector_distortion=keep_projector_distortion,
                                             report=report))
    Rig.from_dict(rig, where=str(path))        # every field checked as a rig file would be
    return rig


def _node_value(node, path: Path, key: str):
    """A FileStorage node as a numpy array (a matrix, a sequence of numbers or one number); ConfigError naming
    ``key`` for text or anything else that is not numbers."""
    import cv2

    if node.isString():
        raise ConfigError(f"{path}: {key}: expected a matrix or numbers, found the text {node.string()[:40]!r}")
    if node.isSeq():
        items = [node.at(i) for i in range(node.size())]
        if not all(item.isReal() or item.isInt() for item in items):
            raise ConfigError(f"{path}: {key}: expected a sequence of numbers, found other items in it")
        return np.array([item.real() for item in items], dtype=np.float64)
    if node.isReal() or node.isInt():
        return np.array(node.real(), dtype=np.float64)
    try:
        m = node.mat()
    except cv2.error:
        raise ConfigError(f"{path}: {key}: expected a matrix (!!opencv-matrix) or numbers, found something "
                          f"else") from None
    return None if m is None else np.asarray(m, dtype=np.float64)


def _duplicate_keys(path: Path) -> list[str]:
    """The top-level keys an OpenCV YAML or XML file gives more than once (FileStorage keeps one silently)."""
    import re

    text = read_regular_file(path, what="a calibration file").decode("utf-8", errors="replace")
    if path.suffix.lower() == ".xml":
        depth, keys = 0, []
        for m in re.finditer(r"<(/?)([A-Za-z_][\w.-]*)([^>]*?)(/?)>", text):
            closing, name, _, empty = m.groups()
            if closing:
                depth -= 1
                continue
            if depth == 1:
                keys.append(name)
            if not empty:
                depth += 1
    else:
        keys = re.findall(r"^([A-Za-z_][\w.-]*)\s*:", text, flags=re.MULTILINE)
    seen, twice = set(), []
    for key in keys:
        if key in seen and key not in twice:
            twice.append(key)
        seen.add(key)
    return twice


def read_opencv(path: Path) -> dict:
    import cv2

    twice = _duplicate_keys(path)
    if twice:
        raise ConfigError(f"{path}: expected each key once, found {', '.join(map(repr, twice))} given more than once "
                          "(OpenCV would keep one of them without a word): keep the one you mean")

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:     # SystemError: cv2's binding over a parse error
        cause = exc.__cause__ or exc
        raise ConfigError(f"{path}: expected an OpenCV FileStorage file (YAML/XML), found one OpenCV cannot "
                          f"read ({(str(cause).strip().splitlines() or ['?'])[-1]})") from None
    if not fs.isOpened():
        raise ConfigError(f"{path}: expected an OpenCV FileStorage file (YAML/XML), found one OpenCV cannot open")
    try:
        root = fs.root()
        return {k: _node_value(root.getNode(k), path, k) for k in root.keys()}
    finally:
        fs.release()


def _first(values: dict, field: str, path: Path, *, required: bool = True):
    for key in OPENCV_KEYS[field]:
        if values.get(key) is not None:
            return key, values[key]
    if required:
        raise ConfigError(f"{path}: expected one of the keys {', '.join(OPENCV_KEYS[field])} ({field}), found "
                          f"none; the file has {', '.join(values) or 'no keys'}")
    return None, None


def _size(values: dict, field: str, prefix: str, label: str, given, option: str, path: Path) -> tuple[int, int]:
    key, v = _first(values, field, path, required=False)
    if v is None and values.get(f"{prefix}_width") is not None and values.get(f"{prefix}_height") is not None:
        key, v = f"{prefix}_width/{prefix}_height", np.array([values[f"{prefix}_width"], values[f"{prefix}_height"]])
    if v is None:
        if given is None:
            raise ConfigError(f"{path}: expected the {label} size (keys {', '.join(OPENCV_KEYS[field])} or "
                              f"{prefix}_width and {prefix}_height), found none; give it with {option} WxH")
        return given
    v = np.asarray(v, dtype=np.float64).ravel()
    if v.size != 2 or not np.all(v == np.round(v)) or not np.all(v > 0):
        raise ConfigError(f"{path}: {key}: expected [width, height] in pixels, found {found_value(v)}")
    return int(v[0]), int(v[1])


def opencv_rig(path: Path, *, size=None, projector_size=None, unit: str = "m", values: dict | None = None) -> dict:
    """Camera + projector from an OpenCV stereo calibration (module doc: the keys read); ``values``: the file's
    keys, already read."""
    if unit not in UNIT_SCALES:
        raise ConfigError(f"{path}: unit: expected one of {', '.join(UNIT_SCALES)}, found {unit!r}")
    values = read_opencv(path) if values is None else values
    keys = {f: _first(values, f, path) for f in ("camera_K", "camera_dist", "projector_K", "projector_dist", "R", "T")}
    cam_size = _size(values, "camera_size", "image", "camera image", size, "--size", path)
    proj_size = _size(values, "projector_size", "projector", "projector", projector_size, "--projector-size", path)
    return procam_rig(path, keys, unit, cam_size, proj_size, UNITS, _UNIT_FIXES)
