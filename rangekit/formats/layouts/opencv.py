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


#: The most frames an image list may name per camera: a capture is tens of frames, an HDR one hundreds
#: (OpenCV's FileNode finds item k by walking k items, so a list of 200,000 took over a minute to read).
MAX_LIST_ENTRIES = 10_000
#: The largest image list read, bytes (10,000 paths of 1 KB).
MAX_LIST_BYTES = 10 << 20


def read_image_list(path: str | Path) -> list[list[Path]]:
    """The files of each camera (one or two lists) in an image list as OpenCV's ``pointcloud.cpp`` reads it:
    the first node a sequence (camera 1), then ``cam2`` (camera 2) if there. A relative name is relative to the
    list's folder. FileFormatError naming the file and what is missing or wrong: a file OpenCV cannot parse
    (binary, nested too deep), an XML document type or entity (never expanded), more than
    :data:`MAX_LIST_ENTRIES` names."""
    import cv2

    from rangekit.regular_files import read_regular_file

    path = Path(path)
    if path.stat().st_size > MAX_LIST_BYTES:
        raise FileFormatError(f"{path}: expected an OpenCV image list of at most {MAX_LIST_BYTES >> 20} MB, found "
                              f"{path.stat().st_size / 2**20:.0f} MB")
    head = read_regular_file(path, what="an image list")
    if b"\0" in head:
        raise FileFormatError(f"{path}: expected an OpenCV image list (YAML or XML text), found binary data")
    if b"<!DOCTYPE" in head.upper() or b"<!ENTITY" in head.upper():
        raise FileFormatError(f"{path}: expected an OpenCV image list, found an XML document type or entity "
                              "declaration (not expanded: remove it)")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError, RecursionError) as exc:    # SystemError: cv2's binding over a parse error
        said = (str(exc.__cause__ or exc).strip().splitlines() or ["?"])[-1]
        raise FileFormatError(f"{path}: expected an OpenCV image list (YAML or XML), found one OpenCV cannot parse "
                              f"({said.split('error: ')[-1][:160]})") from None
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
            if node.size() > MAX_LIST_ENTRIES:
                raise FileFormatError(f"{path}: expected at most {MAX_LIST_ENTRIES} frames a camera, found "
                                      f"{node.size()} in {node.name() or 'the first node'}")
            items = [node.at(k) for k in range(node.size())]
            if not all(item.isString() for item in items):
                raise FileFormatError(f"{path}: expected {node.name() or 'the first node'} to list file names, found "
                                      "other items in it")
            names = [item.string() for item in items]
            lists.append([p if p.is_absolute() else path.parent / p for p in map(Path, names)])
    finally:
        fs.release()
    return lists
