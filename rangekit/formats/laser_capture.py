"""A laser-line capture folder: one turntable position, the laser-off image and one image per laser.

::

    off.png                 the laser-off (ambient) image
    laser0.png, laser1.png  laser k on, the others off (one per entry of the rig file's 'lasers')
    rig.json                the rig file, with its 'lasers'
    capture.json            optional: how it was taken (the simulator writes its settings there)
    ground_truth.npz        optional: the simulator's truth

``rangekit sim render --sensor laser`` writes one; ``rangekit reconstruct`` reads it.

A two-camera laser capture (laser-sheet stereo, :mod:`rangekit.laser.sheet_stereo`) holds the same frames per
camera, and needs no laser plane::

    left/off.png, left/laser0.png, ...    the left camera's (rig.json's cameras[0]) laser-off and laser frames
    right/off.png, right/laser0.png, ...  the right camera's (cameras[1], on the left camera's +x side)
    rig.json                the rig file: the two cameras (calibrated as a pair), the turntable; 'lasers' optional
    capture.json            kind "rangekit.laser_stereo/1", n_lasers (frames per camera besides off.png);
                            optional: channels (each laser's colour: red, green, blue or white; default the rig
                            file's lasers', else red), turntable_angle_rad (default 0), the simulator's settings
    ground_truth.npz        optional: the simulator's truth

``rangekit sim render --sensor laser-stereo`` writes one; ``rangekit reconstruct`` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import math

import numpy as np

from rangekit.errors import FileFormatError, shown
from rangekit.image_header import check_image_files
from rangekit.formats.capture import capture_full_scale
from rangekit.io import read_json, read_png
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["LaserCapture", "is_laser_capture", "load_laser_capture", "LASER_STEREO_KIND", "LaserStereoCapture",
           "is_laser_stereo_capture", "load_laser_stereo_capture"]

LASER_STEREO_KIND = "rangekit.laser_stereo/1"
#: Lasers a two-camera capture may hold (as :data:`rangekit.laser.sequence.MAX_LASERS`).
_MAX_LASERS = 8
_CHANNELS = ("red", "green", "blue", "white")


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
                              f"and {RIG_FILE}")
    rig = rig if rig is not None else load_rig(folder / RIG_FILE)
    if not rig.lasers:
        raise FileFormatError(f"{folder / RIG_FILE}: no 'lasers'; a laser capture needs the lasers' planes "
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
                              f"{RIG_FILE} is {cam.width}x{cam.height}")
    info = read_json(folder / "capture.json", what="capture description") if (folder / "capture.json").exists() else {}
    return LaserCapture(folder, rig, images[0], tuple(images[1:]), info if isinstance(info, dict) else {})


@dataclass(frozen=True, eq=False)
class LaserStereoCapture:
    """A two-camera laser capture as read: per camera (``left``, ``right``) the laser-off image and one frame per
    laser; the ``rig`` (its cameras[0] and [1]); each laser's colour ``channels``; the turntable ``angle``
    (radians); ``info`` the capture.json."""

    folder: Path
    rig: Rig
    off: tuple[np.ndarray, np.ndarray]
    frames: tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]
    channels: tuple[str, ...]
    angle: float
    info: dict

    @property
    def n_lasers(self) -> int:
        return len(self.channels)

    @property
    def full_scale(self) -> float | None:
        """The cameras' largest pixel value (capture.json's imaging bits, else the rig file's); None: the dtype's."""
        return capture_full_scale(self.info, self.rig)

    def path(self, side: int, k: int | None) -> Path:
        """The file of camera ``side`` (0 left, 1 right), laser ``k`` (None: the laser-off image)."""
        return self.folder / ("left", "right")[side] / ("off.png" if k is None else f"laser{k}.png")


def is_laser_stereo_capture(folder: str | Path) -> bool:
    """A folder whose ``capture.json`` says it is a two-camera laser capture."""
    path = Path(folder) / "capture.json"
    try:
        return path.is_file() and read_json(path, what="capture description").get("kind") == LASER_STEREO_KIND
    except (FileFormatError, AttributeError, OSError):
        return False


def _stereo_info(folder: Path) -> tuple[dict, int, tuple[str, ...] | None, float]:
    """capture.json's fields, checked: (info, n_lasers, channels or None, angle)."""
    where = folder / "capture.json"
    info = read_json(where, what="capture description")
    if not isinstance(info, dict) or info.get("kind") != LASER_STEREO_KIND:
        found = info.get("kind") if isinstance(info, dict) else type(info).__name__
        raise FileFormatError(f"{where}: kind: expected {LASER_STEREO_KIND!r}, found {shown(found)}")
    n = info.get("n_lasers")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= _MAX_LASERS:
        raise FileFormatError(f"{where}: n_lasers: expected the number of laser frames per camera, 1 to {_MAX_LASERS}, "
                              f"found {shown(n)}")
    channels = info.get("channels")
    if channels is not None and (not isinstance(channels, list) or len(channels) != n
                                 or any(c not in _CHANNELS for c in channels)):
        raise FileFormatError(f"{where}: channels: expected {n} laser colour(s) from {', '.join(_CHANNELS)}, found "
                              f"{str(channels)[:120]}")
    angle = info.get("turntable_angle_rad", 0.0)
    if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not math.isfinite(angle):
        raise FileFormatError(f"{where}: turntable_angle_rad: expected a finite angle in radians, found {shown(angle)}")
    return info, n, None if channels is None else tuple(channels), float(angle)


def load_laser_stereo_capture(folder: str | Path, rig: Rig | str | Path | None = None) -> LaserStereoCapture:
    """Read a two-camera laser capture folder (module doc); ``rig`` (a Rig or a rig file) replaces its rig.json.
    Errors name the file, the expected and the found value."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder; expected a two-camera laser capture with left/, right/, "
                              f"{RIG_FILE} and capture.json")
    info, n, channels, angle = _stereo_info(folder)
    rig_where = rig if isinstance(rig, (str, Path)) else folder / RIG_FILE if rig is None else "the rig given"
    rig = rig if isinstance(rig, Rig) else load_rig(rig_where)
    if len(rig.cameras) < 2:
        raise FileFormatError(f"{rig_where}: cameras: a two-camera laser capture needs the calibrated pair (left = "
                              f"cameras[0], right = cameras[1]), found {len(rig.cameras)} camera(s)")
    if channels is None:
        channels = tuple(laser.channel for laser in rig.lasers) if len(rig.lasers) == n else ("red",) * n
    names = ["off.png"] + [f"laser{k}.png" for k in range(n)]
    paths = [[folder / side / name for name in names] for side in ("left", "right")]
    missing = [str(p.relative_to(folder)) for side in paths for p in side if not p.is_file()]
    if missing:
        raise FileFormatError(f"{folder}: capture.json says {n} laser(s), so the folder needs left/ and right/ with "
                              f"{', '.join(names)} each; missing {', '.join(missing)}")
    check_image_files(paths[0] + paths[1], what="a two-camera laser capture", same_size=False)   # the budget
    images = []
    for side, cam in zip(paths, rig.cameras[:2]):
        header = check_image_files(side, what=f"camera {cam.name!r}'s laser frames")[0]   # one size and depth
        size = (header.width, header.height) if header is not None else None
        if size is None:
            imgs = [read_png(p) for p in side]
            size = (imgs[0].shape[1], imgs[0].shape[0])
        if size != (cam.width, cam.height):
            raise FileFormatError(f"{side[0]}: image is {size[0]}x{size[1]} but camera {cam.name!r} in {rig_where} is "
                                  f"{cam.width}x{cam.height} (width x height)")
        images.append(imgs if header is None else [read_png(p) for p in side])
    return LaserStereoCapture(folder, rig, (images[0][0], images[1][0]), (tuple(images[0][1:]), tuple(images[1][1:])),
                              channels, angle, info)
