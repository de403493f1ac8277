"""kamino410's procam-calibration capture folders (github kamino410/procam-calibration, ``gen_graycode_imgs.py``
and ``calibrate.py``).

- ``procam:graycode``: one folder per capture, ``capture_N/graycode_00.png ...``: the frames of OpenCV's
  ``GrayCodePattern`` (columns then rows, each bit from the most significant with its inverse), then white,
  then black (the tool appends them). With ``-graycode_step 1``, the tool's default, each code is one projector
  pixel; a larger step (codes of step x step pixels) is not a preset.
"""

from __future__ import annotations

from rangekit.coded.patterns import PatternSpec
from rangekit.formats.layouts.layout import CaptureLayout
from rangekit.formats.layouts.opencv import opencv_graycode_frames

__all__ = ["PROCAM_LAYOUTS"]

PROCAM_LAYOUTS = {
    "procam:graycode": CaptureLayout(
        "procam:graycode", "kamino410/procam-calibration gen_graycode_imgs.py, calibrate.py", "graycode_{:02d}.png",
        lambda w, h: PatternSpec("graycode", w, h).n_frames, lambda w, h: PatternSpec("graycode", w, h),
        opencv_graycode_frames),
}
