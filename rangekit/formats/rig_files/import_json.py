"""``rangekit rig import`` of the vendors' JSON calibrations (see :mod:`rangekit.formats.rig_files.importers`).

**depthai** (``CalibrationHandler.eepromToJson()``, e.g. an OAK-D's EEPROM): ``cameraData`` is a list of
``[socket, camera]`` pairs (socket 0 = CAM_A, 1 = CAM_B, 2 = CAM_C, ...); each camera has ``width``,
``height``, ``intrinsicMatrix`` (3x3 pixels), ``distortionCoeff`` (14, OpenCV order) and ``extrinsics``
with ``rotationMatrix`` (float32 on the device: projected onto the nearest rotation), ``translation`` {x, y, z} in **centimetres** and ``toCameraSocket`` (-1: none):
``X_to = R X_this + t``; a baseline ``|t|`` outside :data:`rangekit.rig.plausibility.BASELINE` is refused or
warned of. World = CAM_A's frame (else the lowest socket); every camera linked to it through
the extrinsics is listed, the world camera first. No projector, no turntable.

**Horus** ``calibration.json`` (Ciclop scanner; its profile file, the settings either at the top or under
``calibration_settings``, each value either plain or ``{"value": ...}`` as Horus saves it):
``camera_matrix`` (3x3), ``distortion_vector`` (5), ``distance_left``/``normal_left`` and
``distance_right``/``normal_right`` (the laser planes in the camera frame, ``n . X = distance``, mm),
``rotation_matrix`` and ``translation_vector`` (the platform: ``X_cam = R X_platform + t``, mm; the
turntable's axis is the platform's z). World = the camera's frame. The image size is Horus's
``camera_width`` x ``camera_height``, transposed with ``camera_rotate`` (on by default: Horus transposes and
flips every frame and calibrates on the result; a rangekit driver must deliver the frames the same way).
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import ConfigError, shown as found_value
from rangekit.formats.rig_files.entries import camera_entry, rig_dict
from rangekit.geometry import invert_T, make_T, nearest_rotation
from rangekit.rig.lasers import LineLaser, laser_plane
from rangekit.rig.plausibility import BASELINE, check_length, format_vector

__all__ = ["depthai_rig", "horus_rig", "DEPTHAI_SOCKETS"]

DEPTHAI_SOCKETS = {0: "CAM_A", 1: "CAM_B", 2: "CAM_C", 3: "CAM_D", 4: "CAM_E", 5: "CAM_F"}


def _array(value, shape, where: str, key: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != shape or not np.all(np.isfinite(a)):
        found = "not numbers" if a is None else f"shape {a.shape}" if a.shape != shape else "non-finite values"
        raise ConfigError(f"{where}: {key}: expected {'x'.join(map(str, shape))} finite numbers, found {found}")
    return a


def _xyz(value, where: str, key: str) -> np.ndarray:
    if not isinstance(value, dict) or not all(k in value for k in "xyz"):
        raise ConfigError(f"{where}: {key}: expected {{\"x\", \"y\", \"z\"}}, found {found_value(value)}")
    return _array([value["x"], value["y"], value["z"]], (3,), where, key)


def _rotation(value, where: str, key: str) -> np.ndarray:
    """A 3x3 rotation stored in float32 (depthai's EEPROM): orthonormal to about 1e-7, so projected onto the
    nearest rotation (a rig file asks for 1e-9); one off by more than 1e-4 is refused."""
    R = _array(value, (3, 3), where, key)
    off = float(np.abs(R @ R.T - np.eye(3)).max())
    if off > 1e-4 or np.linalg.det(R) <= 0:
        raise ConfigError(f"{where}: {key}: expected a rotation (orthonormal, det +1), found max |R R^T - I| = "
                          f"{off:.2g}, det {np.linalg.det(R):.4g}")
    return nearest_rotation(R)


def depthai_rig(data: dict, where: str) -> dict:
    """The rig of a depthai EEPROM calibration (module doc)."""
    entries = data.get("cameraData")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{where}: cameraData: expected a list of [socket, camera] pairs, found {entries!r:.80}")
    cams, links = {}, {}
    for i, entry in enumerate(entries):
        key = f"cameraData[{i}]"
        if not (isinstance(entry, list) and len(entry) == 2 and isinstance(entry[0], int) and isinstance(entry[1], dict)):
            raise ConfigError(f"{where}: {key}: expected [socket number, {{camera}}], found {entry!r:.80}")
        socket, cam = entry
        for field in ("width", "height", "intrinsicMatrix", "distortionCoeff"):
            if field not in cam:
                raise ConfigError(f"{where}: {key}.{field}: expected it, found no such key")
        cams[socket] = cam
        ext = cam.get("extrinsics") or {}
        to = ext.get("toCameraSocket", -1)
        if isinstance(to, int) and to >= 0:
            R = _rotation(ext.get("rotationMatrix"), where, f"{key}.extrinsics.rotationMatrix")
            t = _xyz(ext.get("translation"), where, f"{key}.extrinsics.translation") * 0.01   # cm -> m
            check_length(float(np.linalg.norm(t)), BASELINE, where=where, read_as="cm",
                         shown=f"{key}.extrinsics.translation = {format_vector(t * 100)} cm",
                         what=f"baseline from socket {socket} to socket {to}")
            links[(to, socket)] = make_T(R, t)                 # T_to_this
            links[(socket, to)] = invert_T(links[(to, socket)])
    world = 0 if 0 in cams else min(cams)
    T_world = {world: np.eye(4)}
    frontier = [world]
    while frontier:                                           # every camera reachable from the world's
        a = frontier.pop()
        for (p, q), T_p_q in links.items():
            if p == a and q not in T_world and q in cams:
                T_world[q] = T_world[a] @ T_p_q
                frontier.append(q)
    cameras = []
    for socket in sorted(T_world, key=lambda s: (s != world, s)):
        cam, key = cams[socket], f"cameraData[socket {socket}]"
        name = DEPTHAI_SOCKETS.get(socket, f"socket{socket}")
        K = _array(cam["intrinsicMatrix"], (3, 3), where, f"{key}.intrinsicMatrix")
        dist = np.asarray(cam["distortionCoeff"], dtype=np.float64).ravel()
        if dist.size != 14:
            raise ConfigError(f"{where}: {key}.distortionCoeff: expected 14 numbers, found {dist.size}")
        cameras.append(camera_entry(name, K, dist, (cam["width"], cam["height"]), T_world[socket],
                                    f"{where}: {key}.intrinsicMatrix"))
    devices = {"camera": {"type": "depthai", "id": None, "socket": DEPTHAI_SOCKETS.get(world, "CAM_A"),
                          "search_timeout_s": 3.0}}
    return rig_dict(cameras, None, None, devices)


def _horus_value(settings: dict, key: str, where: str):
    if key not in settings:
        raise ConfigError(f"{where}: {key}: expected it (a Horus calibration.json), found no such key")
    v = settings[key]
    return v["value"] if isinstance(v, dict) and "value" in v else v


def _horus_size(settings: dict, where: str) -> tuple[int, int]:
    """The size of the images Horus calibrated on: its capture size ``camera_width`` x ``camera_height``,
    transposed when ``camera_rotate`` is on (Horus transposes every frame, then flips it as ``camera_hflip``
    / ``camera_vflip`` say; the intrinsics are those of the transformed image)."""
    if "camera_width" not in settings or "camera_height" not in settings:
        raise ConfigError(f"{where}: expected the camera's image size (camera_width, camera_height), found "
                          "none; give it with --size WxH (Ciclop's camera: 1280x960, 960x1280 rotated)")
    w, h = (_horus_value(settings, k, where) for k in ("camera_width", "camera_height"))
    if not all(isinstance(v, int) and v > 0 for v in (w, h)):
        raise ConfigError(f"{where}: camera_width, camera_height: expected positive whole numbers, found "
                          f"{found_value(w)}, {found_value(h)}")
    rotate = "camera_rotate" not in settings or bool(_horus_value(settings, "camera_rotate", where))  # Horus: on
    return (h, w) if rotate else (w, h)


def horus_rig(data: dict, where: str, *, size: tuple[int, int] | None) -> dict:
    """The rig of a Horus ``calibration.json`` (module doc): camera, two line lasers, the turntable."""
    settings = data.get("calibration_settings", data)
    if not isinstance(settings, dict):
        raise ConfigError(f"{where}: calibration_settings: expected an object, found {settings!r:.80}")
    size = size or _horus_size(settings, where)
    K = _array(_horus_value(settings, "camera_matrix", where), (3, 3), where, "camera_matrix")
    dist = np.asarray(_horus_value(settings, "distortion_vector", where), dtype=np.float64).ravel()
    if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise ConfigError(f"{where}: distortion_vector: expected 4, 5, 8, 12 or 14 finite numbers, found "
                          f"{found_value(dist)}")
    R = _array(_horus_value(settings, "rotation_matrix", where), (3, 3), where, "rotation_matrix")
    t = _array(_horus_value(settings, "translation_vector", where), (3,), where, "translation_vector") * 1e-3
    lasers = []
    for side in ("left", "right"):
        n = _array(_horus_value(settings, f"normal_{side}", where), (3,), where, f"normal_{side}")
        d = float(_array(_horus_value(settings, f"distance_{side}", where), (), where, f"distance_{side}")) * 1e-3
        if not 0.5 < np.linalg.norm(n) < 2.0:
            raise ConfigError(f"{where}: normal_{side}: expected a unit normal, found length {np.linalg.norm(n):.3g}")
        n = n / np.linalg.norm(n)
        plane = laser_plane(n, n * d, towards=np.zeros(3))     # n . X = d, stored towards the camera
        lasers.append(LineLaser(plane=plane, name=side).to_dict())
    camera = camera_entry("camera", K, dist, size, np.eye(4), f"{where}: camera_matrix")
    devices = {"turntable": {"protocol": "horus", "port": "/dev/ttyUSB0", "baud": 115200}}   # a UVC camera: no driver
    return rig_dict([camera], None, make_T(R, t), devices, lasers)
