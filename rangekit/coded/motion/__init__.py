"""Motion during a coded-light capture (issue 38 item 3): :mod:`rangekit.coded.motion.check` (the check of binary
codes), :mod:`rangekit.coded.motion._kernels` (its compiled loops)."""

from rangekit.coded.motion.check import MAX_MOTION_SHARE, MOTION_LIMIT_CODES, MotionCheck, check_motion

__all__ = ["MAX_MOTION_SHARE", "MOTION_LIMIT_CODES", "MotionCheck", "check_motion"]
