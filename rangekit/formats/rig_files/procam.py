"""The rig file of two devices related by ``cv2.stereoCalibrate``'s ``R``, ``T`` (``rangekit rig import``): a
camera and a projector, or two cameras. The part every such importer shares (:mod:`.importers` for OpenCV
stereo files, :mod:`.import_tools` for the structured-light tools' files), and the one place their matrices
are checked, each refusal naming the file's key."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError, shown as found_value
from rangekit.formats.rig_files.entries import camera_entry, rig_dict
from rangekit.geometry import invert_T, make_T, nearest_rotation
from rangekit.rig.plausibility import BASELINE, UNIT_SCALES, check_length, format_vector
from rangekit.rig.rig_file import template_rig

__all__ = ["procam_rig", "ROTATION_TOLERANCE"]

#: Largest ``max |R R^T - I|`` re-orthonormalised (a file written in float32, as SLStudio's, is orthonormal to
#: ~1e-7 only); a matrix further from a rotation is refused.
ROTATION_TOLERANCE = 1e-6
_DIST_COUNTS = (4, 5, 8, 12, 14)


def procam_rig(path: Path, keys: dict, unit: str, cam_size, proj_size, units, fixes: dict, *,
               second: str = "projector") -> dict:
    """The rig file of a camera and a projector (``second="projector"``) or of two cameras
    (``second="camera"``, named "cam1" and "cam2").

    ``keys`` maps camera_K, camera_dist, projector_K, projector_dist (the second device's, a camera's too),
    R and T to (key in the file, value), with ``X_second = R X_cam + T`` (``cv2.stereoCalibrate``'s convention)
    and ``T`` in ``unit`` (a key of :data:`rangekit.rig.plausibility.UNIT_SCALES`); ``cam_size`` /
    ``proj_size``: (width, height) pixels. World = the first camera's frame; no turntable. The baseline is
    checked by :data:`BASELINE` (``units``: the units guessed for a baseline out of range; ``fixes``: the
    advice for each). Raises ConfigError naming the file and the key of a matrix of the wrong shape, a
    non-positive focal length, a distortion of an unknown length or a matrix that is not a rotation."""
    import cv2

    rkey, R = keys["R"]
    R = np.asarray(R, dtype=np.float64)
    if R.size == 3:
        R = cv2.Rodrigues(R.reshape(3, 1))[0]
    error = np.abs(R @ R.T - np.eye(3)).max() if R.shape == (3, 3) and np.all(np.isfinite(R)) else np.inf
    if not error <= ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        found = f"max |R R^T - I| = {error:.2g}, det {np.linalg.det(R):.4g}" if np.isfinite(error) else \
            f"shape {R.shape}" if R.shape != (3, 3) else "values that are not finite"
        raise ConfigError(f"{path}: {rkey}: expected a 3x3 rotation (orthonormal within {ROTATION_TOLERANCE:g}, "
                          f"determinant +1) or a Rodrigues vector, found {found}: {found_value(R)}")
    R = nearest_rotation(R)   # a file written in float32 (SLStudio's) is orthonormal to 1e-7 only
    tkey, t = keys["T"]
    t = np.asarray(t, dtype=np.float64).ravel()
    if t.size != 3 or not np.all(np.isfinite(t)):
        raise ConfigError(f"{path}: {tkey}: expected 3 finite numbers, found {found_value(t)}")
    what = "camera-projector baseline" if second == "projector" else "stereo baseline"
    check_length(float(np.linalg.norm(t)) * UNIT_SCALES[unit], BASELINE, where=str(path), read_as=unit,
                 units=units, shown=f"{tkey} = {format_vector(t)} {unit}", what=what, fixes=fixes)
    T_second_cam = make_T(R, t * UNIT_SCALES[unit])
    names = ("camera", "projector") if second == "projector" else ("cam1", "cam2")
    first = camera_entry(names[0], *_intrinsics(path, keys["camera_K"], keys["camera_dist"]), cam_size, np.eye(4),
                         f"{path}: {keys['camera_K'][0]}")
    other = camera_entry(names[1], *_intrinsics(path, keys["projector_K"], keys["projector_dist"]), proj_size,
                         invert_T(T_second_cam), f"{path}: {keys['projector_K'][0]}")
    devices = {k: v for k, v in template_rig()["devices"].items()}
    if second == "projector":
        return rig_dict([first], other, None, devices)
    return rig_dict([first, other], None, None, devices)


def _intrinsics(path: Path, K_entry, dist_entry) -> tuple[np.ndarray, np.ndarray]:
    """A camera matrix and its distortion, each (key, value), checked as OpenCV's pinhole model has them."""
    kkey, K = K_entry
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ConfigError(f"{path}: {kkey}: expected a finite 3x3 camera matrix, found "
                          f"{'shape ' + str(K.shape) if K.shape != (3, 3) else found_value(K)}")
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ConfigError(f"{path}: {kkey}: expected positive focal lengths fx, fy (pixels), found fx = "
                          f"{K[0, 0]:.6g}, fy = {K[1, 1]:.6g}")
    if K[0, 1] != 0 or K[1, 0] != 0 or np.any(K[2] != (0.0, 0.0, 1.0)):
        raise ConfigError(f"{path}: {kkey}: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (OpenCV's, no skew), "
                          f"found {found_value(K)}")
    dkey, d = dist_entry
    d = np.asarray(d, dtype=np.float64).ravel()
    if d.size not in _DIST_COUNTS or not np.all(np.isfinite(d)):
        raise ConfigError(f"{path}: {dkey}: expected {', '.join(map(str, _DIST_COUNTS[:-1]))} or "
                          f"{_DIST_COUNTS[-1]} finite OpenCV distortion coefficients, found {d.size}: "
                          f"{found_value(d)}")
    return K, d
