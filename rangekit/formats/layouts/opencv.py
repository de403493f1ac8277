"""OpenCV's structured-light capture folders (opencv_contrib ``modules/structured_light``).

- ``opencv:graycode`` (``GrayCodePattern``, ``src/graycodepattern.cpp``; files as its samples
  ``cap_pattern.cpp`` write them and ``pointcloud.cpp`` reads them): ``pattern_cam1_im1.png ...``, numbered
  from 1: for columns, then rows, each bit from the most significant, the bit's frame then its inverse
  (``ceil(log2(size))`` bits per axis), then white, then black: 2 (11 + 10) + 2 = 44 frames for 1280x800.
  A bit is 1 where the frame is brighter than its inverse (rangekit's rule). ``.jpg`` files (the samples'
  test data) are read as well; a stereo capture's second camera is ``pattern_cam2_im...``.
- ``opencv:psp``, ``opencv:faps``, ``opencv:ftp`` (``SinusoidalPattern``, ``src/sinusoidalpattern.cpp``; files as
  ``samples/capsinpattern.cpp`` names its captures, ``<prefix>_PSP_0.png ...`` and ``<prefix>_FAPS_0.png ...``,
  ``_FTP_`` by analogy: the sample saves none for FTP): the three fringe frames (FTP: one), then the three
  frames of one period across the screen that rangekit needs for an absolute column (rangekit's ``psp``,
  ``faps``, ``ftp`` methods, :mod:`rangekit.coded.codecs.fringes`). OpenCV's sample records no such cue: it
  cycles its three frames, so files 3-5 of its folder repeat 0-2 (refused, found more frames than the
  layout has); record the cue as files 3-5 (OpenCV's generate() with one period), or render it with rangekit.
  Markers, OpenCV's own way to an absolute phase, need the calibration at decoding and are not read.
- The image list ``pointcloud.cpp`` reads (:func:`read_image_list`): an OpenCV FileStorage (YAML or XML) whose
  first node is the sequence of camera 1's files and whose ``cam2`` node is camera 2's, each in the order
  above.
"""

from __future__ import annotations

from pathlib import Path

from rangekit.coded.patterns import PatternSpec
from rangekit.errors import FileFormatError
from rangekit.formats.layouts.layout import CaptureLayout

__all__ = ["OPENCV_LAYOUTS", "opencv_graycode_frames", "read_image_list"]


def _spec(width: int, height: int) -> PatternSpec:
    return PatternSpec("graycode", width, height)


def opencv_graycode_frames(width: int, height: int) -> tuple:
    """Per frame of rangekit's graycode spec, the index of OpenCV's file holding it (0-based)."""
    spec = _spec(width, height)
    order = spec.frame_names_in("opencv")
    return tuple(order.index(name) for name in spec.frame_names)


def _sinusoidal(method: str):
    return lambda w, h: PatternSpec(method, w, h, ("columns",))


OPENCV_LAYOUTS = {
    "opencv:graycode": CaptureLayout(
        "opencv:graycode", "opencv_contrib modules/structured_light/src/graycodepattern.cpp, "
        "samples/cap_pattern.cpp, samples/pointcloud.cpp", "pattern_cam{camera}_im{index}.png",
        lambda w, h: _spec(w, h).n_frames, _spec, opencv_graycode_frames, first_index=1,
        other_names=("pattern_cam{camera}_im{index}.jpg",)),
    **{f"opencv:{method}": CaptureLayout(
        f"opencv:{method}", "opencv_contrib modules/structured_light/src/sinusoidalpattern.cpp, "
        "samples/capsinpattern.cpp", f"*_{method.upper()}_{{index}}.png",
        (lambda m: lambda w, h: _sinusoidal(m)(w, h).n_frames)(method), _sinusoidal(method),
        (lambda m: lambda w, h: tuple(range(_sinusoidal(m)(w, h).n_frames)))(method))
       for method in ("psp", "faps", "ftp")},
}


def read_image_list(path: str | Path) -> list[list[Path]]:
    """The files of each camera (one or two lists) in an image list as OpenCV's ``pointcloud.cpp`` reads it:
    the first node a sequence (camera 1), then ``cam2`` (camera 2) if there. A relative name is relative to the
    list's folder. FileFormatError naming the file and what is missing."""
    import cv2

    path = Path(path)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        if not fs.isOpened():
            raise FileFormatError(f"{path}: expected an OpenCV image list (YAML or XML), found a file OpenCV cannot "
                                  "read")
        first = fs.getFirstTopLevelNode()
        nodes = [first] + ([fs.getNode("cam2")] if first.name() != "cam2" and not fs.getNode("cam2").empty()
                           else [])
        lists = []
        for node in nodes:
            if not node.isSeq() or node.size() == 0:
                raise FileFormatError(f"{path}: expected {node.name() or 'the first node'} to be a sequence of image "
                                      "file names, found none")
            names = [node.at(k).string() for k in range(node.size())]
            lists.append([p if p.is_absolute() else path.parent / p for p in map(Path, names)])
    finally:
        fs.release()
    return lists
