"""OpenCV's structured-light capture folders (opencv_contrib ``modules/structured_light``).

- ``opencv:graycode`` (``GrayCodePattern``, ``src/graycodepattern.cpp``; files as its samples
  ``cap_pattern.cpp`` write them and ``pointcloud.cpp`` reads them): ``pattern_cam1_im1.png ...``, numbered
  from 1: for columns, then rows, each bit from the most significant, the bit's frame then its inverse
  (``ceil(log2(size))`` bits per axis), then white, then black: 2 (11 + 10) + 2 = 44 frames for 1280x800.
  A bit is 1 where the frame is brighter than its inverse (rangekit's rule). ``.jpg`` files (the samples'
  test data) are read as well; a stereo capture's second camera is ``pattern_cam2_im...``.
"""

from __future__ import annotations

from rangekit.coded.patterns import PatternSpec
from rangekit.formats.layouts.layout import CaptureLayout

__all__ = ["OPENCV_LAYOUTS", "opencv_graycode_frames"]


def _spec(width: int, height: int) -> PatternSpec:
    return PatternSpec("graycode", width, height)


def opencv_graycode_frames(width: int, height: int) -> tuple:
    """Per frame of rangekit's graycode spec, the index of OpenCV's file holding it (0-based)."""
    spec = _spec(width, height)
    order = spec.frame_names_in("opencv")
    return tuple(order.index(name) for name in spec.frame_names)


OPENCV_LAYOUTS = {
    "opencv:graycode": CaptureLayout(
        "opencv:graycode", "opencv_contrib modules/structured_light/src/graycodepattern.cpp, "
        "samples/cap_pattern.cpp, samples/pointcloud.cpp", "pattern_cam{camera}_im{index}.png",
        lambda w, h: _spec(w, h).n_frames, _spec, opencv_graycode_frames, first_index=1,
        other_names=("pattern_cam{camera}_im{index}.jpg",)),
}
