"""The rig file of one camera and one projector from a calibration's matrices (``rangekit rig import``): the
part every camera-projector importer shares (:mod:`.importers` for OpenCV stereo files, :mod:`.import_tools`
for the structured-light tools' files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError
from rangekit.formats.rig_files.entries import camera_entry, rig_dict
from rangekit.geometry import invert_T, make_T, nearest_rotation
from rangekit.rig.plausibility import BASELINE, check_length, format_vector
from rangekit.rig.rig_file import template_rig

__all__ = ["procam_rig"]


def procam_rig(path: Path, keys: dict, unit: str, cam_size, proj_size, units: dict, fixes: dict) -> dict:
    """The rig file of a camera and a projector: ``keys`` maps camera_K, camera_dist, projector_K, projector_dist,
    R and T to (key in the file, value), with ``X_proj = R X_cam + T`` (``T`` in ``unit``, one of ``units``:
    metres per unit); the baseline is checked (``fixes``: the advice for each likely unit)."""
    import cv2

    rkey, R = keys["R"]
    R = np.asarray(R, dtype=np.float64)
    if R.size == 3:
        R = cv2.Rodrigues(R.reshape(3, 1))[0]
    if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) \
            or np.linalg.det(R) <= 0:
        raise ConfigError(f"{path}: {rkey}: expected a 3x3 rotation (orthonormal, determinant +1) or a Rodrigues "
                          f"vector, found {np.round(R, 4).tolist()}")
    R = nearest_rotation(R)   # a file written in float32 (SLStudio's) is orthonormal to 1e-7 only
    tkey, t = keys["T"]
    t = np.asarray(t, dtype=np.float64).ravel()
    if t.size != 3 or not np.all(np.isfinite(t)):
        raise ConfigError(f"{path}: {tkey}: expected 3 finite numbers, found {t.tolist()}")
    check_length(float(np.linalg.norm(t)) * units[unit], BASELINE, where=str(path), read_as=unit, units=units,
                 shown=f"{tkey} = {format_vector(t)} {unit}", what="camera-projector baseline", fixes=fixes)
    T_proj_cam = make_T(R, t * units[unit])
    camera = camera_entry("camera", keys["camera_K"][1], keys["camera_dist"][1], cam_size, np.eye(4),
                          f"{path}: {keys['camera_K'][0]}")
    projector = camera_entry("projector", keys["projector_K"][1], keys["projector_dist"][1], proj_size,
                             invert_T(T_proj_cam), f"{path}: {keys['projector_K'][0]}")
    devices = {k: v for k, v in template_rig()["devices"].items()}
    return rig_dict([camera], projector, None, devices)
