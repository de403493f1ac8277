"""A laser-line capture folder: one turntable position, the laser-off image and one image per laser.

::

    off.png                 the laser-off (ambient) image
    laser0.png, laser1.png  laser k on, the others off (one per entry of the rig file's 'lasers')
    rig.json                the rig file, with its 'lasers'
    capture.json            optional: how it was taken (the simulator writes its settings there)
    ground_truth.npz        optional: the simulator's truth

``rangekit sim render --sensor laser`` writes one; ``rangekit reconstruct`` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError
from rangekit.image_header import check_image_files
from rangekit.formats.capture import capture_full_scale
from rangekit.io import read_json, read_png
from rangekit.rig.rig_file import Rig, load_rig

__all__ = ["LaserCapture", "is_laser_capture", "load_laser_capture"]


@dataclass(frozen=True, eq=False)
class LaserCapture:
    """``off`` (H, W[, 3]) and ``frames`` (one per laser, same shape and dtype) with the ``rig``."""

    folder: Path
    rig: Rig
    off: np.ndarray
    frames: tuple[np.ndarray, ...]
    info: dict   # capture.json, {} when absent

    @property
    def full_scale(self) -> float | None:
        """The camera's largest pixel value (a 12-bit camera in 16-bit PNGs: 4095); None: the dtype's."""
        return capture_full_scale(self.info, self.rig)

    @property
    def names(self) -> list[str]:
        return [f"laser{k}.png" for k in range(len(self.frames))]


def is_laser_capture(folder: str | Path) -> bool:
    """A folder holding ``off.png`` and ``laser0.png`` (a laser-line capture, not a coded-light one)."""
    folder = Path(folder)
    return (folder / "off.png").is_file() and (folder / "laser0.png").is_file()


def load_laser_capture(folder: str | Path, rig: Rig | None = None) -> LaserCapture:
    """Read a laser capture folder; ``rig`` replaces its rig.json. Errors name the file, the expected and the
    found value."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder; expected a laser capture with off.png, laser0.png ... "
                              "and rig.json")
    rig = rig if rig is not None else load_rig(folder / "rig.json")
    if not rig.lasers:
        raise FileFormatError(f"{folder / 'rig.json'}: no 'lasers'; a laser capture needs the lasers' planes "
                              "(calibrate them with rangekit calibrate --lasers, docs/rig.md)")
    paths = [folder / "off.png"] + [folder / f"laser{k}.png" for k in range(len(rig.lasers))]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise FileFormatError(f"{folder}: the rig file has {len(rig.lasers)} laser(s), so the folder needs "
                              f"{', '.join(p.name for p in paths)}; missing {', '.join(missing)}")
    check_image_files(paths, what="a laser capture")
    images = [read_png(p) for p in paths]
    cam = rig.camera
    if images[0].shape[:2] != (cam.height, cam.width):
        raise FileFormatError(f"{paths[0]}: image is {images[0].shape[1]}x{images[0].shape[0]} but the camera in "
                              f"rig.json is {cam.width}x{cam.height}")
    info = read_json(folder / "capture.json", what="capture description") if (folder / "capture.json").exists() else {}
    return LaserCapture(folder, rig, images[0], tuple(images[1:]), info if isinstance(info, dict) else {})
