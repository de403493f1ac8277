"""A view's motion check on a pair of lines in every ``step``: whether the object held still, at a fraction of the
full check's cost, for the scan and the processing to refuse (and re-capture) a view without changing any pixel of
a still one.

:func:`rangekit.coded.motion.check.check_motion` flags every pixel; it needs each axis's stripe-edge crossings over
the whole image (about 0.17 CPU-s a 1280x1024 view). Whether more than a share of a view moved is a count, and the
stripes a move displaces run across the whole object, so some lines tell it: the column codes' edges along camera
rows 0, 1, step, step + 1, ..., the row codes' along those camera columns (the lines the crossings run along are
kept whole). The lines come in pairs so that the check reads them as it reads the whole image: a flag is kept where
the neighbouring line along the stripe is flagged too (the other line of its pair), the bits a region does not read
are found over tiles of :data:`READ_TILE_PX` camera pixels (:data:`READ_SIGMAS`, issue 47), and a neighbourhood of
about :data:`REGION_HALF_PX` camera pixels either way decides where most moved. (On single lines 8 apart, the
neighbour along the stripe was 8 pixels away: with the rule of the bits read, a 2 mm knock on the small rig fell
from 5.0% to 0.9% moved; on pairs 16 apart, as many lines, it is 6.0%.) The share is then the larger of the two
axes' shares of the decoded pixels on their lines, and the frames named are both axes' (:class:`MotionCheck`; its
``mask`` is left empty: nothing is flagged).
"""

from __future__ import annotations

import numpy as np

from rangekit.coded.binary import axis_code
from rangekit.coded.frames import CaptureStack
from rangekit.coded.motion.check import READ_SIGMAS, READ_TILE_PX, REGION_HALF_PX, MotionCheck, check_motion
from rangekit.coded.patterns import PatternSpec

__all__ = ["DETECT_STEP", "MOTION_METHODS", "detect_motion", "line_pairs"]

#: Every how many camera lines the detector checks a pair (lines 0, 1, 16, 17, ...: one line in 8).
DETECT_STEP = 16
#: The patterns whose Gray or XOR bits the check reads (the hybrid's Gray part included).
MOTION_METHODS = ("graycode", "xor02", "xor04", "hybrid")


def detect_motion(stack: np.ndarray, spec: PatternSpec, decoded: np.ndarray, *, order: str = "rangekit",
                  step: int = DETECT_STEP, read_sigmas: float = READ_SIGMAS) -> MotionCheck:
    """Whether the object moved during the capture ``stack`` ((K, H, W) grey, in ``order``), checked on a pair of
    lines in every ``step`` (module doc). ``decoded``: (H, W) bool, the pixels with a projector code;
    ``read_sigmas``: :func:`rangekit.coded.motion.check.check_motion`'s (0: every bit read, the rule before issue
    47). Returns the :class:`MotionCheck` with an all-False ``mask``, ``share`` the larger axis's share,
    ``moved_frames`` both axes' (in capture order), ``undersampled`` the axes whose codes the camera does not
    resolve (not checked)."""
    H, W = decoded.shape
    share, moved, undersampled, offsets = 0.0, set(), [], {}
    for axis in spec.axes:
        pairs = line_pairs(H if axis == "columns" else W, step)
        lines = (pairs, slice(None)) if axis == "columns" else (slice(None), pairs)
        fr = CaptureStack(_pairs_of(stack, axis == "rows", step), spec, order)
        code = axis_code(fr, spec, axis, 1, 96)
        tile, half = _pair_windows(axis, step)
        got = check_motion(fr, spec, {axis: code}, decoded[lines], read_sigmas=read_sigmas, tile=tile,
                           region_half=half, line_pairs=True)
        share = max(share, got.share)
        moved.update(got.moved_frames)
        undersampled += list(got.undersampled)
        offsets.update(got.bit_offsets)
    order_of = {name: i for i, name in enumerate(spec.frame_names)}
    return MotionCheck(np.zeros((H, W), bool), share, tuple(sorted(moved, key=order_of.__getitem__)), offsets,
                       tuple(undersampled))


def line_pairs(n: int, step: int) -> np.ndarray:
    """The lines checked of ``n``: each ``step``-th line and the one after it (lines 0, 1, step, step + 1, ...)."""
    first = np.arange(0, n - 1, step)
    return np.sort(np.r_[first, first + 1])


def _pair_windows(axis: str, step: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """:func:`rangekit.coded.motion.check.check_motion`'s ``tile`` and ``region_half`` (rows, columns) on the line
    pairs of ``axis`` (its lines are rows for column codes, columns for row codes): across the lines, a tile of
    :data:`READ_TILE_PX` camera pixels is ``2 READ_TILE_PX / step`` lines, a half of :data:`REGION_HALF_PX` pixels
    ``2 REGION_HALF_PX / step`` rounded up (at least one line each)."""
    tile_lines, half_lines = max(2 * READ_TILE_PX // step, 1), max(-(-2 * REGION_HALF_PX // step), 1)
    if axis == "columns":
        return (tile_lines, READ_TILE_PX), (half_lines, REGION_HALF_PX)
    return (READ_TILE_PX, tile_lines), (REGION_HALF_PX, half_lines)


def _pairs_of(stack: np.ndarray, columns: bool, step: int) -> np.ndarray:
    """(K, 2 n, W) the :func:`line_pairs` rows of ``stack`` (K, H, W), or (K, H, 2 n) its columns (``columns``); a
    colour stack (K, H, W, 3) keeps its channels. Two strided copies (fancy indexing of columns: 15x slower)."""
    stack = np.asarray(stack)
    n = len(line_pairs(stack.shape[2] if columns else stack.shape[1], step)) // 2
    shape = (stack.shape[0], stack.shape[1], 2 * n) if columns else (stack.shape[0], 2 * n, stack.shape[2])
    out = np.empty(shape + stack.shape[3:], stack.dtype)
    lines = (slice(None), slice(None)) if columns else (slice(None),)
    for j in range(2):
        out[lines + (slice(j, None, 2),)] = stack[lines + (slice(j, j + (n - 1) * step + 1, step),)]
    return out
