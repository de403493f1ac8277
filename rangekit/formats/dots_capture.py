"""A random-dot sensor's capture folder (one camera, a dot projector, a reference image; Kinect v1 style): what
``rangekit sim render --sensor dots`` writes and ``rangekit reconstruct DIR`` reads (:mod:`rangekit.stereo.dots`).

The folder holds:

* ``image.png``: the camera's raw image of the scene under the dots;
* ``reference.png``: its raw image of the same dots on a plane facing it (the sensor's reference), the same size;
* ``rig.json``: the camera as ``cameras[0]`` and the dot projector as ``projector`` (its pose: the baseline);
* ``capture.json``: ``{"kind": "rangekit.dots/1", "reference_distance_m": Z0}``, the plane's distance along the
  camera's optical axis in metres;
* optionally ``ground_truth.npz`` from the simulator (depth, xyz, hit, valid).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError, shown
from rangekit.image_header import check_image_files
from rangekit.io import read_json, read_png
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["DOTS_KIND", "DotsFolder", "is_dots_capture", "load_dots_capture"]

DOTS_KIND = "rangekit.dots/1"


@dataclass(frozen=True, eq=False)
class DotsFolder:
    """A dot-sensor capture folder as read: the two images ((H, W) raw), the rig, the reference distance (m)."""

    folder: Path
    image: np.ndarray
    reference: np.ndarray
    rig: Rig
    reference_distance: float


def is_dots_capture(folder: str | Path) -> bool:
    """A folder whose ``capture.json`` says it is a dot-sensor capture."""
    path = Path(folder) / "capture.json"
    try:
        return path.is_file() and read_json(path, what="capture description").get("kind") == DOTS_KIND
    except (FileFormatError, AttributeError, OSError):
        return False


def load_dots_capture(folder: str | Path, rig: Rig | None = None) -> DotsFolder:
    """Read a dot-sensor capture folder (module doc); ``rig`` replaces its rig.json. Errors name the file, the
    expected and the found value."""
    folder = Path(folder)
    info = read_json(folder / "capture.json", what="capture description")
    z0 = info.get("reference_distance_m") if isinstance(info, dict) else None
    if isinstance(z0, bool) or not isinstance(z0, (int, float)) or not math.isfinite(z0) or z0 <= 0:
        raise FileFormatError(f"{folder / 'capture.json'}: reference_distance_m: expected the reference plane's "
                              f"distance in metres (> 0), found {shown(z0)}")
    rig = rig if rig is not None else load_rig(folder / RIG_FILE)
    if not rig.cameras or rig.projector is None:
        raise FileFormatError(f"{folder / RIG_FILE}: a dot sensor needs its camera (cameras[0]) and its dot "
                              f"projector (projector), found {len(rig.cameras)} camera(s) and "
                              f"{'a' if rig.projector is not None else 'no'} projector")
    paths = [folder / "image.png", folder / "reference.png"]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise FileFormatError(f"{folder}: a dot-sensor capture needs image.png and reference.png; missing "
                              f"{', '.join(missing)}")
    check_image_files(paths, what="a dot-sensor capture", same_size=False)
    image, reference = read_png(paths[0]), read_png(paths[1])
    cam = rig.cameras[0]
    for path, img in zip(paths, (image, reference)):
        if img.shape[:2] != (cam.height, cam.width):
            raise FileFormatError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, expected the camera's "
                                  f"{cam.width}x{cam.height} ({RIG_FILE})")
    return DotsFolder(folder, image, reference, rig, float(z0))
