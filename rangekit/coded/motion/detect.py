"""A view's motion check on every ``step``-th line: whether the object held still, at a fraction of the full check's
cost, for the scan and the processing to refuse (and re-capture) a view without changing any pixel of a still one.

:func:`rangekit.coded.motion.check.check_motion` flags every pixel; it needs each axis's stripe-edge crossings over
the whole image (about 0.17 CPU-s a 1280x1024 view). Whether more than a share of a view moved is a count, and the
stripes a move displaces run across the whole object, so every ``step``-th line tells it: the column codes' edges
along every ``step``-th camera row, the row codes' along every ``step``-th camera column (the lines the crossings
run along are kept whole). The share is then the larger of the two axes' shares of the decoded pixels on their
lines, and the frames named are both axes' (:class:`MotionCheck`; its ``mask`` is left empty: nothing is flagged).
"""

from __future__ import annotations

import numpy as np

from rangekit.coded.binary import axis_code
from rangekit.coded.frames import CaptureStack
from rangekit.coded.motion.check import MotionCheck, check_motion
from rangekit.coded.patterns import PatternSpec

__all__ = ["DETECT_STEP", "MOTION_METHODS", "detect_motion"]

#: Every how many camera lines the detector checks.
DETECT_STEP = 8
#: The patterns whose Gray or XOR bits the check reads (the hybrid's Gray part included).
MOTION_METHODS = ("graycode", "xor02", "xor04", "hybrid")


def detect_motion(stack: np.ndarray, spec: PatternSpec, decoded: np.ndarray, *, order: str = "rangekit",
                  step: int = DETECT_STEP) -> MotionCheck:
    """Whether the object moved during the capture ``stack`` ((K, H, W) grey, in ``order``), checked on every
    ``step``-th line (module doc). ``decoded``: (H, W) bool, the pixels with a projector code. Returns the
    :class:`MotionCheck` with an all-False ``mask``, ``share`` the larger axis's share, ``moved_frames`` both axes'
    (in capture order), ``undersampled`` the axes whose codes the camera does not resolve (not checked)."""
    H, W = decoded.shape
    share, moved, undersampled, offsets = 0.0, set(), [], {}
    for axis in spec.axes:
        lines = (slice(None, None, step), slice(None)) if axis == "columns" else (slice(None), slice(None, None, step))
        fr = CaptureStack(np.ascontiguousarray(stack[(slice(None),) + lines]), spec, order)
        code = axis_code(fr, spec, axis, 1, 96)
        # Every bit read, weak or not (read_sigmas 0): on every 8th line the weak bits' rule of the pixel check
        # (READ_SIGMAS) left a 2 mm knock on the small rig (fine stripes blurred) at 0.9% moved, under max_motion.
        got = check_motion(fr, spec, {axis: code}, decoded[lines], read_sigmas=0.0)
        share = max(share, got.share)
        moved.update(got.moved_frames)
        undersampled += list(got.undersampled)
        offsets.update(got.bit_offsets)
    order_of = {name: i for i, name in enumerate(spec.frame_names)}
    return MotionCheck(np.zeros((H, W), bool), share, tuple(sorted(moved, key=order_of.__getitem__)), offsets,
                       tuple(undersampled))
