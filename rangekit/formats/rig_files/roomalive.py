"""RoomAlive Toolkit's ``ProjectorCameraEnsemble`` XML (``rangekit rig import``): a Kinect v2 and a projector.

Read from RoomAlive's source (github microsoft/RoomAliveToolkit, ``ProCamCalibration/ProCamEnsembleCalibration``:
``Calibrate.cs`` the ensemble and its calibration, ``Kinect2Calibration.cs`` the Kinect's, ``CameraMath.cs`` the
projection). The file is .NET's ``XmlSerializer`` of the ensemble; every matrix is ``<ValuesByColumn>``, one
``<ArrayOfDouble>`` per column. Lengths are metres (the depth is divided by 1000 before the calibration).

- ``cameras/Camera``: ``pose`` (4x4, the depth camera's frame to RoomAlive's world; the first camera's is the
  identity) and ``calibration``: ``colorCameraMatrix``, ``colorLensDistortion`` (k1, k2), ``depthCameraMatrix``,
  ``depthLensDistortion`` (k1, k2), ``depthToColorTransform`` (depth camera points to colour camera points).
  Image sizes are the Kinect v2's: colour 1920 x 1080, depth 512 x 424 (constants of ``Kinect2Calibration``).
- ``projectors/Projector``: ``width``, ``height``, ``cameraMatrix``, ``lensDistortion`` (k1, k2), ``pose`` (the
  projector's frame to the world: ``UnifyPose`` sets it to camera pose x inverse of the depth-to-projector pose).
- Projection (``CameraMath.Project``): ``u = fx x' (1 + k1 r^2 + k2 r^4) + cx`` with ``x' = X / Z``: OpenCV's
  radial model, (k1, k2, 0, 0, 0).

**Frames and pixels.** RoomAlive's camera frames are the Kinect SDK's, x to the left, y up, z ahead
(``Calibrate.cs``: "X left, Y up"). A colour image pixel (column, row) is ``(u, 1080 - v)``
(``Kinect2Calibration`` fits the SDK's colour points with ``Y = 1080 - Y``; ``CalibrateProjectorGroups`` looks
pixels up at ``(round(u), 1080 - round(v))``); the depth image likewise (``424 - v``). The projector's decoded
column and row are ``(width - u, height - v)``. So the Kinect's images, as stored, are mirror images of the room
(the Kinect SDK delivers them flipped left to right, "Our Gray code images are flipped in the horizontal
direction"), while the projector's are not: no rotation relates them. rangekit's rig describes the Kinect's
images **flipped left to right** (``numpy.fliplr``: column ``x`` becomes ``width - 1 - x``), as a camera sees
the room; the ``roomalive:graycode`` layout and :func:`rangekit.formats.range_files.read_kinect_depth` flip
them so. In OpenCV's frame (x right, y down: RoomAlive's rotated half a turn about z, ``N = diag(-1, -1, 1)``):

- colour camera ``[[fx, 0, 1919 - cx], [0, fy, 1080 - cy]]``, depth camera ``[[fx, 0, 511 - cx], [0, fy, 424 -
  cy]]``, projector ``[[fx, 0, width - cx], [0, fy, height - cy]]``; the radial distortion is unchanged;
- world = the colour camera's frame (as every import); depth camera ``T_world_depth = N D N`` (``D`` the
  depthToColorTransform); projector ``T_world_proj = N D C^-1 P N`` (``C`` the camera's pose, ``P`` the
  projector's).

The rig file's ``cameras`` are the colour camera ("kinect_colour") then the depth camera ("kinect_depth");
``projector`` is the projector. An ensemble of more than one camera or projector, or one not calibrated yet
(RoomAlive's "New" ensemble before Acquire and Calibrate: no ``calibration``, a 0 x 0 projector), is refused in
one line.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError, shown as found_value
from rangekit.formats.rig_files.entries import camera_entry, rig_dict
from rangekit.formats.rig_files.procam import ROTATION_TOLERANCE
from rangekit.geometry import invert_T, nearest_rotation
from rangekit.regular_files import read_regular_file
from rangekit.rig.plausibility import BASELINE, check_length, format_vector
from rangekit.rig.rig_file import template_rig

__all__ = ["COLOUR_SIZE", "DEPTH_SIZE", "ROOT", "is_roomalive", "roomalive_rig", "N_FLIP"]

ROOT = "ProjectorCameraEnsemble"
#: The Kinect v2's image sizes (``Kinect2Calibration``'s constants; not in the file).
COLOUR_SIZE, DEPTH_SIZE = (1920, 1080), (512, 424)
#: RoomAlive's camera frame (x left, y up) to OpenCV's (x right, y down): half a turn about z.
N_FLIP = np.diag([-1.0, -1.0, 1.0, 1.0])
_MAX_BYTES = 1 << 22
_CALIBRATION = ("colorCameraMatrix", "colorLensDistortion", "depthCameraMatrix", "depthLensDistortion",
                "depthToColorTransform")


def is_roomalive(path: Path) -> bool:
    """Whether ``path`` (an .xml) opens with RoomAlive's ensemble element (its first 4 kB)."""
    with open(path, "rb") as f:
        head = f.read(4096)
    return f"<{ROOT}".encode() in head


def roomalive_rig(path: str | Path, *, report=None) -> dict:
    """The rig file (module doc: frames, pixels) of the RoomAlive ensemble in ``path``; ConfigError naming the
    file and the element of anything missing or malformed. ``report``: told what was read."""
    path = Path(path)
    data = read_regular_file(path, what="a RoomAlive ensemble", limit=_MAX_BYTES)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise ConfigError(f"{path}: expected RoomAlive's ProjectorCameraEnsemble XML, found XML that does not "
                          f"parse ({exc})") from None
    if root.tag != ROOT:
        raise ConfigError(f"{path}: expected the root element {ROOT}, found {root.tag}")
    cameras, projectors = root.findall("cameras/Camera"), root.findall("projectors/Projector")
    if len(cameras) != 1 or len(projectors) != 1:
        raise ConfigError(f"{path}: expected an ensemble of one camera and one projector (a rig has one projector), "
                          f"found {len(cameras)} camera(s) and {len(projectors)} projector(s)")
    camera, projector = cameras[0], projectors[0]
    calibration = camera.find("calibration")
    size = tuple(_integer(projector, key, path) for key in ("width", "height"))
    if calibration is None or projector.find("pose") is None:
        raise ConfigError(f"{path}: expected a calibrated ensemble (cameras/Camera/calibration and projectors/"
                          f"Projector/pose), found {'no calibration' if calibration is None else 'no projector pose'}"
                          f" and a {size[0]}x{size[1]} projector: an ensemble before RoomAlive's Acquire and "
                          f"Calibrate, nothing to import")
    m = {key: _matrix(calibration, key, path) for key in _CALIBRATION}
    C = _pose(camera, "pose", path, "cameras/Camera/pose")
    D = _pose(calibration, "depthToColorTransform", path, "depthToColorTransform", m["depthToColorTransform"])
    P = _pose(projector, "pose", path, "projectors/Projector/pose")
    if not all(v > 0 for v in size):
        raise ConfigError(f"{path}: projectors/Projector/width, height: expected a size in pixels, found "
                          f"{size[0]}x{size[1]}")
    T_world_depth = N_FLIP @ D @ N_FLIP
    T_world_proj = N_FLIP @ D @ invert_T(C) @ P @ N_FLIP
    baseline = T_world_proj[:3, 3]
    check_length(float(np.linalg.norm(baseline)), BASELINE, where=str(path), read_as="m",
                 units=("mm",), shown=f"the projector at {format_vector(baseline)} m", what="camera-projector baseline",
                 fixes={"mm": "RoomAlive writes metres: is the file edited?"})
    entries = [
        camera_entry("kinect_colour", _flipped(m["colorCameraMatrix"], COLOUR_SIZE, 1, path, "colorCameraMatrix"),
                     _radial(m["colorLensDistortion"], path, "colorLensDistortion"), COLOUR_SIZE, np.eye(4),
                     f"{path}: colorCameraMatrix"),
        camera_entry("kinect_depth", _flipped(m["depthCameraMatrix"], DEPTH_SIZE, 1, path, "depthCameraMatrix"),
                     _radial(m["depthLensDistortion"], path, "depthLensDistortion"), DEPTH_SIZE, T_world_depth,
                     f"{path}: depthCameraMatrix")]
    Kp = _matrix(projector, "cameraMatrix", path)
    proj = camera_entry("projector", _flipped(Kp, size, 0, path, "projectors/Projector/cameraMatrix"),
                        _radial(_matrix(projector, "lensDistortion", path), path, "lensDistortion"), size,
                        T_world_proj, f"{path}: projectors/Projector/cameraMatrix")
    if report is not None:
        report(f"{path}: read as RoomAlive's ProjectorCameraEnsemble (metres); the Kinect's images flipped left to "
               f"right (roomalive:graycode and read_kinect_depth flip them so)")
    return rig_dict(entries, proj, None, dict(template_rig()["devices"]))


def _integer(element, key: str, path: Path) -> int:
    node = element.find(key)
    try:
        return int(node.text)
    except (AttributeError, TypeError, ValueError):
        raise ConfigError(f"{path}: {key}: expected a whole number, found "
                          f"{'no element' if node is None else repr(node.text)}") from None


def _matrix(element, key: str, path: Path) -> np.ndarray:
    """``element/key/ValuesByColumn``: one ArrayOfDouble per column."""
    node = element.find(f"{key}/ValuesByColumn")
    if node is None:
        raise ConfigError(f"{path}: {key}: expected a matrix (ValuesByColumn), found none")
    try:
        columns = [[float(d.text) for d in column.findall("double")] for column in node.findall("ArrayOfDouble")]
        m = np.array(columns, dtype=np.float64).T
    except (TypeError, ValueError):
        raise ConfigError(f"{path}: {key}: expected columns of numbers (ArrayOfDouble), found others") from None
    if m.ndim != 2 or m.size == 0 or not np.all(np.isfinite(m)):
        raise ConfigError(f"{path}: {key}: expected a matrix of finite numbers, found {found_value(m)}")
    return m


def _pose(element, key: str, path: Path, shown: str, m=None) -> np.ndarray:
    """A 4x4 rigid transform (rotation within :data:`ROTATION_TOLERANCE`, re-orthonormalised)."""
    m = _matrix(element, key, path) if m is None else m
    if m.shape != (4, 4) or np.any(m[3] != (0.0, 0.0, 0.0, 1.0)):
        raise ConfigError(f"{path}: {shown}: expected a 4x4 rigid transform, found {found_value(m)}")
    R = m[:3, :3]
    error = float(np.abs(R @ R.T - np.eye(3)).max())
    if not error <= ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise ConfigError(f"{path}: {shown}: expected a rotation (orthonormal within {ROTATION_TOLERANCE:g}, "
                          f"determinant +1), found max |R R^T - I| = {error:.2g}, det {np.linalg.det(R):.4g}")
    out = m.copy()
    out[:3, :3] = nearest_rotation(R)
    return out


def _flipped(K: np.ndarray, size, col_offset: int, path: Path, key: str) -> np.ndarray:
    """RoomAlive's camera matrix as OpenCV's for the image flipped left to right (module doc): ``cx' = W - 1 - cx``
    for the Kinect (``col_offset`` 1: a stored column is u) or ``W - cx`` for the projector (0: the decoded column is
    ``W - u``), ``cy' = H - cy``."""
    if K.shape != (3, 3) or not (K[0, 0] > 0 and K[1, 1] > 0) or K[0, 1] != 0 or np.any(K[2] != (0, 0, 1)):
        raise ConfigError(f"{path}: {key}: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, found "
                          f"{found_value(K)}")
    out = K.copy()
    out[0, 2] = size[0] - col_offset - K[0, 2]
    out[1, 2] = size[1] - K[1, 2]
    return out


def _radial(d: np.ndarray, path: Path, key: str) -> np.ndarray:
    d = d.ravel()
    if d.size != 2:
        raise ConfigError(f"{path}: {key}: expected 2 radial coefficients (k1, k2), found {d.size}: {found_value(d)}")
    return np.array([d[0], d[1], 0.0, 0.0, 0.0])
