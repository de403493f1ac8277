"""The rig file: cameras, projector, turntable axis, and how to reach each device (JSON, versioned).

Schema ``rangekit.rig/1`` (every field is documented in docs/rig.md)::

    {
      "schema": "rangekit.rig/1",
      "cameras": [ {camera}, ... ],          # first is the main camera; see PinholeCamera.to_dict
      "projector": {camera} | null,          # a projector is an inverse camera
      "T_world_table": 4x4 | null,           # turntable frame: rotation axis = its z axis, origin on the axis
      "devices": {...},                      # how to reach each device (serial port, baud, protocol, ...)
      "capture": {...},                      # capture settings (pattern delay, turntable settle time)
      "projector_response": {"gamma": g} | null,  # optional: pattern value p -> relative radiance p ** g
      "lasers": [ {laser}, ... ]             # optional: line lasers (rangekit.rig.lasers.LineLaser.to_dict)
    }

All poses are ``T_world_x`` (maps x's frame to world), metres. A turntable angle theta rotates objects
on the table by ``T_world_table @ Rz(theta) @ inv(T_world_table)``.

:func:`load_rig` checks the geometry and names the file and the field of any error
(``rig.json: cameras[0].dist: ...``). It does not check ``devices`` and ``capture`` beyond their being
objects: :func:`rangekit.rig.checks.validate_rig_for_hardware` does, before any device is opened.
:func:`template_rig` is the starting point for a real rig (``rangekit rig init``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rangekit._runtime.arguments import check_instance, check_items, check_path
from rangekit.budget import MAX_IMAGE_SIDE_PX
from rangekit.camera import PinholeCamera
from rangekit.rig.camera_controls import CameraControls
from rangekit.errors import ConfigError, InputError, shown
from rangekit.geometry import axis_angle_to_R, compose, invert_T, make_T, rigid_problem
from rangekit.io import atomic_write_json, read_json
from rangekit.rig.lasers import LineLaser, laser_from_dict
from rangekit.rig.plausibility import intrinsics_problem
from rangekit.rig.projector_response import ProjectorResponse
from rangekit.rig.checks import CAMERA_TEMPLATES

__all__ = ["Rig", "SCHEMA", "RIG_FIELDS", "CAMERA_FIELDS", "load_rig", "save_rig", "template_rig", "table_motion",
           "turntable_prior", "table_frame"]

SCHEMA = "rangekit.rig/1"
#: The top-level fields of a rig file, in the order :meth:`Rig.to_dict` writes them.
RIG_FIELDS = ("schema", "cameras", "projector", "T_world_table", "devices", "capture", "projector_response",
              "lasers")
#: The fields of one camera or of the projector (:meth:`PinholeCamera.to_dict`).
CAMERA_FIELDS = ("name", "width", "height", "K", "dist", "T_world_cam")
_DIST_SIZES = (0, 4, 5, 8, 12, 14)


@dataclass(frozen=True, eq=False)
class Rig:
    """A scanner's geometry and device settings."""

    cameras: tuple[PinholeCamera, ...]
    projector: PinholeCamera | None = None
    T_world_table: np.ndarray | None = None  # (4, 4); table rotation axis = z of this frame
    devices: dict = field(default_factory=dict)
    capture: dict = field(default_factory=dict)
    projector_response: ProjectorResponse | None = None  # pattern value -> radiance; None: not measured (linear)
    lasers: tuple[LineLaser, ...] = ()  # line lasers fixed to the rig (planes in the world frame)

    def __post_init__(self) -> None:
        cameras = check_items("cameras", self.cameras, "a tuple of PinholeCameras")
        if not cameras:
            raise ConfigError("rig: needs at least one camera in 'cameras'")
        for k, camera in enumerate(cameras):
            check_instance(f"cameras[{k}]", camera, PinholeCamera, "a PinholeCamera")
        check_instance("projector", self.projector, PinholeCamera, "a PinholeCamera", optional=True)
        check_instance("devices", self.devices, dict, "a dict (the rig file's 'devices')")
        check_instance("capture", self.capture, dict, "a dict (the rig file's 'capture')")
        object.__setattr__(self, "cameras", tuple(cameras))
        object.__setattr__(self, "lasers", tuple(check_items("lasers", self.lasers, "a tuple of LineLasers")))
        if not all(isinstance(laser, LineLaser) for laser in self.lasers):
            raise ConfigError("rig: lasers must be LineLaser objects")
        if self.T_world_table is not None:
            object.__setattr__(self, "T_world_table", _rigid(self.T_world_table, "rig", "T_world_table"))
        if self.projector_response is not None and not isinstance(self.projector_response, ProjectorResponse):
            raise ConfigError(f"rig: projector_response must be a ProjectorResponse or None, found "
                              f"{shown(self.projector_response)}")

    @property
    def camera(self) -> PinholeCamera:
        """The main camera (the first one)."""
        return self.cameras[0]

    def T_world_rotated(self, angle: float) -> np.ndarray:
        """(4, 4) motion of the turntable at ``angle`` radians, in world coordinates."""
        if self.T_world_table is None:
            raise ConfigError("rig: no turntable ('T_world_table' is null), so it cannot rotate")
        return table_motion(self.T_world_table, angle)

    def to_dict(self) -> dict:
        return {
            "schema": SCHEMA,
            "cameras": [c.to_dict() for c in self.cameras],
            "projector": None if self.projector is None else self.projector.to_dict(),
            "T_world_table": None if self.T_world_table is None else self.T_world_table.tolist(),
            "devices": self.devices,
            "capture": self.capture,
            "projector_response": None if self.projector_response is None else self.projector_response.to_dict(),
            **({"lasers": [laser.to_dict() for laser in self.lasers]} if self.lasers else {}),
        }

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "rig") -> "Rig":
        """Inverse of :meth:`to_dict`. Errors read ``{where}: {field path}: {problem}``."""
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a JSON object (a rig file), found {type(data).__name__}")
        if data.get("schema") != SCHEMA:
            raise _error(where, "schema", f"must be {SCHEMA!r}, found {shown(data.get('schema'))}")
        unknown = [k for k in data if k not in RIG_FIELDS]
        if unknown:
            raise ConfigError(f"{where}: unknown top-level field(s) {', '.join(map(repr, unknown))}; a rig file "
                              f"has only {', '.join(RIG_FIELDS)}")
        cams = data.get("cameras")
        if not isinstance(cams, list) or not cams:
            raise _error(where, "cameras", f"must be a non-empty list of cameras, found {_show(cams)}")
        cameras = tuple(_camera(c, where, f"cameras[{i}]") for i, c in enumerate(cams))
        proj = data.get("projector")
        projector = None if proj is None else _camera(proj, where, "projector")
        T = data.get("T_world_table")
        T = None if T is None else _rigid(T, where, "T_world_table")
        resp = data.get("projector_response")
        if resp is not None:
            try:
                resp = ProjectorResponse.from_dict(resp, where="projector_response")
            except InputError as exc:
                raise ConfigError(f"{where}: {exc}") from None
        lasers = data.get("lasers", [])
        if not isinstance(lasers, list):
            raise _error(where, "lasers", f"must be a list of lasers, found {_show(lasers)}")
        if len(lasers) > 8:
            raise _error(where, "lasers", f"at most 8 lasers, found {len(lasers)}")
        lasers = tuple(laser_from_dict(entry, where, f"lasers[{i}]") for i, entry in enumerate(lasers))
        for key in ("devices", "capture"):
            if not isinstance(data.get(key, {}), dict):
                raise _error(where, key, f"must be an object ({{...}}), found {_show(data[key])}")
        try:
            return cls(cameras=cameras, projector=projector, T_world_table=T, projector_response=resp, lasers=lasers,
                       devices=dict(data.get("devices", {})), capture=dict(data.get("capture", {})))
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from exc


def table_motion(T_world_table: np.ndarray, angle: float) -> np.ndarray:
    """(4, 4) motion of a turntable turned by ``angle`` radians about its z axis, in world coordinates:
    ``T_world_table @ Rz(angle) @ inv(T_world_table)`` (an object on the table moves by it)."""
    Rz = make_T(axis_angle_to_R([0.0, 0.0, 1.0], angle))
    return compose(T_world_table, Rz, invert_T(T_world_table))


def turntable_prior(T_world_table: np.ndarray, angles) -> np.ndarray:
    """(n, 4, 4) poses ``T_world_view`` of views taken at turntable ``angles`` (radians), world = the
    first view's frame.

    View k saw the object turned by ``M_k = table_motion(T_world_table, angles[k])``, so view k maps into
    view 0 by ``M_0 @ inv(M_k)``. The registration prior of a turntable scan, and the simulator's truth.
    """
    M = [table_motion(T_world_table, float(a)) for a in angles]
    return np.stack([compose(M[0], invert_T(Mk)) for Mk in M])


def table_frame(axis, point=(0.0, 0.0, 0.0)) -> np.ndarray:
    """(4, 4) a turntable frame ``T_world_table`` whose z axis is ``axis`` (normalised) and whose origin is
    ``point`` (metres): the turntable of a rotation axis given as direction and point."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return make_T(np.column_stack([x, np.cross(z, x), z]), np.asarray(point, dtype=np.float64))


#: The extension of a rig file.
RIG_SUFFIXES = (".json",)


def save_rig(rig: Rig, path: str | Path) -> None:
    """Write the rig file atomically."""
    check_instance("rig", rig, Rig, "a rangekit Rig")
    check_path("path", path, what="a rig file")
    atomic_write_json(path, rig.to_dict())


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file; errors name the file and the field."""
    check_path("path", path, what="a rig file")
    return Rig.from_dict(read_json(path, what="rig file"), where=str(path))


def template_rig(camera: str = "depthai") -> dict:
    """A rig file to edit for real hardware (``rangekit rig init > rig.json``); plain JSON types.

    World = the camera's frame (OpenCV: x right, y down, z forward; metres). Placeholders, to be replaced
    by a calibration: a 1280x800 depthai camera (CAM_A) with zero distortion; a 1280x800 projector
    0.2 m to the camera's right, turned towards a point 0.5 m in front of the camera; a turntable
    0.5 m in front of the camera, its top 5 cm below the optical axis, its z axis pointing up (world -y);
    no measured projector response (null: decoded as linear). ``camera``: the camera driver whose section
    ``devices.camera`` holds (:data:`rangekit.rig.checks.CAMERA_TEMPLATES`).
    ``devices`` names a Horus turntable, an ESC/VP21 projector on display 1 refreshing at 60 Hz and a
    depthai camera; ``capture`` holds every capture setting rangekit reads, at its default, the camera's
    controls locked (``CameraControls()``: 33333 us = two 60 Hz periods, ISO 100, 5600 K, lens 130).
    See docs/rig.md.
    """
    if camera not in CAMERA_TEMPLATES:
        raise ConfigError(f"camera: expected one of {', '.join(CAMERA_TEMPLATES)}, found {camera!r}")
    camera_section = dict(CAMERA_TEMPLATES[camera])
    camera = {"name": "camera", "width": 1280, "height": 800,
              "K": [[1000.0, 0.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]],
              "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
              "T_world_cam": np.eye(4).tolist()}
    # The projector sits at x = 0.2 m and is turned about the camera's y axis so that its optical axis
    # passes through (0, 0, 0.5): rotation angle -atan(0.2 / 0.5) about y.
    a = -math.atan2(0.2, 0.5)
    c, s = round(math.cos(a), 12), round(math.sin(a), 12)
    projector = {"name": "projector", "width": 1280, "height": 800,
                 "K": [[1500.0, 0.0, 639.5], [0.0, 1500.0, 399.5], [0.0, 0.0, 1.0]],
                 "dist": [0.0, 0.0, 0.0, 0.0, 0.0],
                 "T_world_cam": [[c, 0.0, s, 0.2], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, 0.0], [0.0, 0.0, 0.0, 1.0]]}
    # Table axes in world (camera) coordinates: x = world x, y = world z (away from the camera),
    # z = world -y (up); origin on the rotation axis at the table top, 0.5 m ahead, 5 cm below the axis.
    T_world_table = [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.05], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]]
    return {
        "schema": SCHEMA,
        "cameras": [camera],
        "projector": projector,
        "T_world_table": T_world_table,
        "devices": {
            "turntable": {"protocol": "horus", "port": "/dev/ttyUSB0", "baud": 115200},
            "projector": {"display": 1, "refresh_hz": 60.0,
                          "control": {"protocol": "escvp21", "port": "/dev/ttyUSB1", "baud": 9600}},
            "camera": camera_section,
        },
        "capture": {"pattern_delay_s": 0.1, "turntable_settle_s": 0.5, "camera": CameraControls().to_dict()},
        "projector_response": None,
    }


# ----------------------------------------------------------------------------- field checks
def _error(where: str, path: str, problem: str) -> ConfigError:
    return ConfigError(f"{where}: {path}: {problem}")


def _show(value) -> str:
    """A short repr of a found value for messages (:func:`rangekit.errors.shown`)."""
    return shown(value)


def _array(value, shape: tuple[int, ...], where: str, path: str, expected: str) -> np.ndarray:
    """A finite float64 array of ``shape``; ``expected`` starts the message ("must be a 3x3 ...")."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _error(where, path, f"{expected}, found {_show(value)}") from None
    if arr.shape != shape:
        raise _error(where, path, f"{expected}, found shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise _error(where, path, f"{expected}, found non-finite values in {_show(value)}")
    return arr


def _rigid(value, where: str, path: str) -> np.ndarray:
    """A (4, 4) rigid transform [[R, t], [0, 0, 0, 1]] (R a rotation: orthonormal, det +1)."""
    T = _array(value, (4, 4), where, path, "must be a 4x4 rigid transform [[R, t], [0, 0, 0, 1]] of finite numbers "
               "(t in metres)")
    problem = rigid_problem(T, tol=1e-9)
    if problem is not None:
        raise _error(where, path, "must be a rigid transform [[R, t], [0, 0, 0, 1]] with R a rotation "
                     f"(orthonormal to 1e-9, det +1); found {problem}")
    return T


def _positive_int(value, where: str, path: str, unit: str, hi: int = MAX_IMAGE_SIDE_PX) -> int:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and float(value).is_integer() and 0 < value <= hi
    if not ok:
        raise _error(where, path, f"must be a positive integer ({unit}) of at most {hi}, found {_show(value)}")
    return int(value)


def _camera(data, where: str, path: str) -> PinholeCamera:
    """One entry of ``cameras`` (or ``projector``), every field checked with its path in the message."""
    if not isinstance(data, dict):
        raise _error(where, path, f"must be an object with K, width, height (and name, dist, T_world_cam), "
                     f"found {_show(data)}")
    unknown = [k for k in data if k not in CAMERA_FIELDS]
    if unknown:
        raise _error(where, path, f"unknown field(s) {', '.join(map(repr, unknown))}; a camera has only "
                     f"{', '.join(CAMERA_FIELDS)}")
    missing = [k for k in ("K", "width", "height") if k not in data]
    if missing:
        raise _error(where, path, f"missing field(s) {', '.join(map(repr, missing))} (every camera and projector "
                     "needs K, width and height)")
    if not isinstance(data.get("name", ""), str):
        raise _error(where, f"{path}.name", f"must be a string, found {_show(data['name'])}")
    for key in ("width", "height"):
        _positive_int(data[key], where, f"{path}.{key}", "pixels")
    K = _array(data["K"], (3, 3), where, f"{path}.K", "the intrinsic matrix 'K' must be a 3x3 array of finite numbers")
    if not (K[0, 0] > 0 and K[1, 1] > 0 and K[0, 1] == 0 and K[1, 0] == 0 and np.array_equal(K[2], [0, 0, 1])):
        raise _error(where, f"{path}.K", "the intrinsic matrix 'K' must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] "
                     f"with fx, fy > 0 and zero skew (as in OpenCV), found {K.tolist()}")
    problem = intrinsics_problem(K, int(data["width"]), int(data["height"]))
    if problem is not None:
        raise _error(where, f"{path}.K", f"implausible intrinsics: {problem}")
    dist = data.get("dist", [])
    try:
        d = np.asarray(dist, dtype=np.float64)
    except (TypeError, ValueError):
        d = None
    if d is None or d.ndim != 1 or d.size not in _DIST_SIZES or not np.all(np.isfinite(d)):
        found = f"{d.size} value(s)" if d is not None and d.ndim == 1 else _show(dist)
        raise _error(where, f"{path}.dist", "must list 0, 4, 5, 8, 12 or 14 finite OpenCV distortion coefficients "
                     f"(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tx, ty]]]]), found {found}")
    if d.size == 14 and np.any(d[12:] != 0):
        raise _error(where, f"{path}.dist", f"the tilted-sensor terms tx, ty must be zero, found {d[12:].tolist()}; "
                     "recalibrate without CALIB_TILTED_MODEL")
    if "T_world_cam" in data:
        _rigid(data["T_world_cam"], where, f"{path}.T_world_cam")
    return PinholeCamera.from_dict(data, where=f"{where}: {path}")
