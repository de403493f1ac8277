"""Motion during a coded-light capture (issue 38 item 3): :mod:`rangekit.coded.motion.check` (the check of binary
codes, pixel by pixel), :mod:`rangekit.coded.motion.detect` (whether a view moved, on a pair of lines in 16: what the
scan and the processing refuse a view by), :mod:`rangekit.coded.motion._kernels` (their compiled loops)."""

from rangekit.coded.motion.check import MAX_CODE_STEP, MAX_MOTION_SHARE, MOTION_LIMIT_CODES, MotionCheck, check_motion
from rangekit.coded.motion.detect import DETECT_STEP, MOTION_METHODS, detect_motion

__all__ = ["DETECT_STEP", "MAX_CODE_STEP", "MAX_MOTION_SHARE", "MOTION_LIMIT_CODES", "MOTION_METHODS", "MotionCheck",
           "check_motion", "detect_motion"]
