"""The names of ``rangekit.coded.motion``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .detect import DETECT_STEP as DETECT_STEP, MOTION_METHODS as MOTION_METHODS, detect_motion as detect_motion
from .check import (MAX_CODE_STEP as MAX_CODE_STEP, MAX_MOTION_SHARE as MAX_MOTION_SHARE,
    MOTION_LIMIT_CODES as MOTION_LIMIT_CODES, MotionCheck as MotionCheck, check_motion as check_motion)
