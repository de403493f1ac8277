"""Motion during a binary-code capture (Fusiello 13.1: a sequential code assumes the scene holds still).

A Gray code (or XOR code) sends each bit of a pixel's projector column in its own frame pair. If the object moves
between two frames, the bits of a pixel come from two surfaces, and its code is one neither surface has.
The codes then disagree between bits, and that is what is checked: between neighbouring camera pixels whose codes
differ by one, exactly one bit changes, and its pattern and inverse cross at that stripe edge
(:func:`rangekit.coded.binary.axis_crossings`). Successive edges along a camera row belong to different bits
(a Gray code's edges run b0, b1, b0, b2, b0, b1, ...), and on a still surface they are evenly spaced up to the
noise: each edge lies on the line through its two neighbours. Where the frames of some bits were taken after the
object moved, their edges are displaced from their neighbours' by the motion, in projector codes:

    residual_n = (pos_n - (pos_{n-1} + pos_{n+1}) / 2) / s        s: camera pixels per code there

(:func:`rangekit.coded.motion._kernels.crossing_residuals`). Where the shift is larger than a stripe, the codes
do not even run one way: ``c+1, c, c+3, c+2`` (the low bits from one surface, the high bits from the other), and
a step back of 2 to 8 codes next to an edge counts as displaced too (a step back of one is the noise at a stripe
edge, a longer one a depth edge). A pixel is flagged in the ``motion`` mask when an edge bracketing it along its row
(or, for row codes, its column) is displaced by more than :data:`MOTION_LIMIT_CODES`, and the same holds for a
neighbour along the stripe (a move displaces a stripe along its length; noise flags a pixel here and there), and
so is every decoded pixel of a neighbourhood where over 15% of the pixels were (:data:`REGION_SHARE`: there the
pixels no edge could check are as suspect).

Only what the capture reads is checked (issue 47: a still real capture is not refused as moved). Where a bit's
pattern and inverse differ by less than :data:`READ_SIGMAS` times their noise (:func:`pair_noise`, the capture's
own), the bit is the noise's: a dark background decoded at a few grey levels of white - black, a fine stripe the
optics blurred away, a coarse stripe interreflection washed out. A step back of the codes whose differing bits are
that weak on both its pixels is such a misread, not a move (NaN, not ``inf``), and a crossing whose pattern -
inverse changes by less than that across its pixel pair is located no better than the noise lets, so it checks no
residual. A move's steps back are read clearly (the simulator's slip: 13 noise sigmas and more).

A bit is read or not over a region too, not only at an edge (a defocused projector: the finest bit pure noise,
the next at a third of its contrast, whose steps back mix the unread bit with readable edges). In each tile of
:data:`READ_TILE_PX` pixels, a bit under that limit on over :data:`UNREAD_SHARE` of the decoded pixels (at its
stripes' peaks too: a resolved stripe is weak only near its edges) is not read there, and the tile is checked with
that bit and every finer one masked off (:func:`unread_levels`): codes ``c >> m``, the Gray code of the bits kept,
whose edges are those bits' own, their residuals and limits in codes of those bits (the simulator with its
projector blurred to a 2-pixel sigma: 40.8% of a still capture flagged without this, none with it). A move leaves
every bit read (the slip: 99.2% caught either way). XOR codes are checked whole (each of their frames holds the
finest stripes).

The frames taken after the move are named from the residuals: each is ``o_b(n) - (o_b(n-1) + o_b(n+1)) / 2`` in
the offsets ``o_b`` of the bits whose edges the three are, solved by least squares in tiles of 64 pixels (a move
shifts the stripes by different amounts, either way, with the slope of the surface), the axis's first-captured
bit with edges in the tile fixed at 0 (a move displaces only the surfaces that slope along it, so the 90th
percentile of each bit's offset over the tiles); a bit displaced by over :data:`NAMED_OFFSET_CODES` and at least
half as much as the most displaced one was captured after the move. Where the move exceeds a stripe, its codes turn
back and leave no residual to solve with: the frames are then named from where it was smaller.

A hybrid without its Gray bits below m (``min_bit``, :attr:`rangekit.coded.patterns.PatternSpec.min_gray_bit`) is
checked otherwise: each edge of its ``2**m`` px Gray blocks (:func:`rangekit.coded.binary.gray_blocks`) against the
phase decoded at the same camera point (:mod:`rangekit.coded.motion.blocks`): on a still object they name the same
projector column whatever the surface's shape, and a move between a bit's frames and the phase frames sets them
apart. The blocks' edges are too far apart (about 11 camera pixels on the default rig) for the spacing of three
to tell a move from the surface's bumps: checked that way, a still upright Stanford bunny was 4.2-9.7% flagged.
The frames taken after a move are named from which bits' edges are off the phase
(:func:`rangekit.coded.motion.blocks.frames_after`).

What it cannot see: a move between the column frames and the row frames, or before the first bit, leaves each
axis's bits consistent among themselves (the capture is then one of the moved object, up to its white and black
frames). A repeat of the reference frames would see it; rangekit's sequences do not carry one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.coded.binary import axis_crossings, edge_bit_lut, gray_blocks
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec, gray_encode

__all__ = ["MAX_CODE_STEP", "MAX_MOTION_SHARE", "MOTION_LIMIT_CODES", "MotionCheck", "check_motion", "code_step",
           "still_baseline", "unread_levels"]

#: A capture in which more of the decoded pixels than this moved is refused by default
#: (:func:`rangekit.coded.decode.decode`'s ``max_motion``, ``rangekit decode --max-motion``).
MAX_MOTION_SHARE = 0.02

#: An axis whose codes step by more than this between neighbouring camera pixels (the median, :func:`code_step`) is
#: not checked: the camera undersamples the projector there, and noise turns codes back as a move would (the
#: suite's 320x256 camera under a 1280x800 projector: 5.8% of a still capture flagged before this guard).
MAX_CODE_STEP = 1.0
#: An edge displaced from its neighbours by more than this many projector codes flags its pixels (a still
#: surface's residuals on the default rig: 0.05 codes at the 90th percentile; 0.25 flagged 0.098% of a still
#: capture, 0.3 0.084%, 0.4 0.055% while missing more: benchmarks/coded/bench_motion.py).
MOTION_LIMIT_CODES = 0.3
#: The limit is at least this many times the capture's own edge noise (:func:`still_baseline`): a still capture's
#: residuals past 3 sigma are 0.3% of its edges, and must also be flagged along the stripe to flag a pixel.
NOISE_SIGMAS = 3.0
#: A pattern minus its inverse under this many times its noise (:func:`pair_noise`) is not read: a step back of the
#: codes whose differing bits are that weak on both its pixels is the noise's (a misread, not a move), and a
#: stripe-edge crossing whose difference changes by less than that across its two pixels is located to no better
#: than sqrt(2)/6 = 0.24 pixels, so it checks no residual. SLStudio's still skull (made inverses, blurred fine
#: stripes, a dark background decoded at 4-20 grey levels of white - black): 46.5% of its decoded pixels flagged
#: without this rule, 0.15% with it; the simulator's 0.5 mm slip turns its codes back with bits 19 grey levels
#: (13 sigma) or more from their inverses at the 10th percentile, and stays 99.2% caught.
READ_SIGMAS = 6.0
#: Largest gap between successive edges (camera pixels) for a residual: wider gaps are not one surface.
EDGE_GAP_PX = 6.0
#: A decoded pixel is flagged too where more than this share of the decoded pixels within :data:`REGION_HALF_PX`
#: moved: the pixels whose code no edge could check (no stripe edge on both sides: the integer code kept), among
#: pixels that moved, are as suspect (on the default rig they held 10% of the pixels a 0.5 mm slip spoiled).
REGION_SHARE = 0.15
#: The frames are named (and the bits' offsets solved) only when more than this share of the pixels moved.
NAMED_SHARE = 0.005
REGION_HALF_PX = 10
#: A bit is not read in a tile of :data:`READ_TILE_PX` pixels where over this share of its decoded pixels have the
#: bit's pattern and inverse within :data:`READ_SIGMAS` noise sigmas (:func:`unread_levels`): its stripes' peaks
#: too (the default rig's bit 0, resolved, is that weak on 16% of its pixels, its edges'). The defocused simulator:
#: nothing flagged with any share from 0.5 to 0.9; SLStudio's skull (fine stripes half read): 0.28% at 0.5 (its
#: tiles checked on their coarser bits, whose edges span the skull's folds), 0.15% at 0.9, as without the rule.
UNREAD_SHARE = 0.9
READ_TILE_PX = 32
#: Frames are named as taken after a move when their bit's edges are displaced by more than this (codes) and by at
#: least half the most displaced bit's: the 90th percentile over tiles of :data:`TILE_PX` pixels with at least
#: :data:`MIN_TILE_EDGES` residuals (a still capture: 0.023 at most on the default rig).
NAMED_OFFSET_CODES = 0.08
TILE_PX = 64
NAMED_PERCENTILE = 90
MIN_TILE_EDGES = 50


@dataclass(frozen=True, eq=False)
class MotionCheck:
    """The motion check of one capture (module doc)."""

    mask: np.ndarray                  # (H, W) bool: pixels whose code mixes frames taken before and after a move
    share: float                      # flagged pixels / decoded pixels
    moved_frames: tuple[str, ...]     # frames whose bits' edges are displaced from the axis's first bit's
    bit_offsets: dict                 # axis -> (nb,) displacement (codes) of each bit's edges, bit 0 first (solved
                                      # only when over NAMED_SHARE moved)
    undersampled: tuple[str, ...] = ()   # axes not checked: the camera does not resolve their codes
                                         # (:data:`MAX_CODE_STEP`)

    def describe(self) -> str:
        """One line for people: the share, and the frames taken after the move."""
        frames = ", ".join(self.moved_frames) if self.moved_frames else "none named"
        unchecked = (f"; {' and '.join(self.undersampled)} not checked (the camera does not resolve their codes)"
                     if self.undersampled else "")
        return (f"{self.share:.1%} of the decoded pixels mix frames taken before and after a move (frames after: "
                f"{frames}){unchecked}")


def check_motion(fr: CaptureStack, spec: PatternSpec, codes: dict[str, np.ndarray], decoded: np.ndarray,
                 crossings: dict[str, np.ndarray] | None = None, limit: float = MOTION_LIMIT_CODES,
                 read_sigmas: float = READ_SIGMAS, tile: tuple[int, int] = (READ_TILE_PX, READ_TILE_PX),
                 region_half: tuple[int, int] = (REGION_HALF_PX, REGION_HALF_PX), line_pairs: bool = False
                 ) -> MotionCheck:
    """The motion check of a binary-code capture (module doc).

    ``fr``: the capture; ``codes``: axis -> (H, W) int32 integer code map (:func:`rangekit.coded.binary.axis_code`;
    a hybrid without its finest Gray bits: its blocks, checked as the module doc says, no frame named);
    ``decoded``: (H, W) bool, the pixels with a code (only they are flagged, and the share is of them);
    ``crossings``: axis -> the axis's crossings when already made (:func:`rangekit.coded.binary.axis_crossings`);
    ``limit``: codes; ``read_sigmas``: bits read under this many noise sigmas are not checked (:data:`READ_SIGMAS`;
    0: every bit is, the check before issue 47); ``tile``: (rows, columns) of the tiles over which a bit is read or
    not (:func:`unread_levels`; pixels of ``fr``); ``region_half``: (rows, columns) of the neighbourhood's half
    size (:data:`REGION_SHARE`); ``line_pairs``: ``fr`` holds pairs of neighbouring camera lines (rows 2k and 2k+1
    of the column codes' frames, columns of the row codes'), each pair's neighbour along a stripe its other line
    (:func:`rangekit.coded.motion.detect.detect_motion`'s layout).
    """
    frame_order = {name: i for i, name in enumerate(spec.frame_names)}
    m = spec.min_gray_bit            # a hybrid without its finest Gray bits: its blocks' edges against the phase
    fr0, spec0 = fr, spec
    fr, spec = gray_blocks(fr, spec)
    mask = np.zeros(fr.shape, bool)
    moved: list[str] = []
    offsets: dict[str, np.ndarray] = {}
    residuals: dict[str, tuple[np.ndarray, ...]] = {}
    after: dict[str, list[str]] = {}           # a hybrid's blocks: each axis's frames taken after a move
    undersampled: list[str] = []
    for axis, code in codes.items():
        c_along = code.T if axis == "rows" else code
        if code_step(c_along, decoded.T if axis == "rows" else decoded) > MAX_CODE_STEP:
            undersampled.append(axis)      # noise turns codes back there: no edge tells a move from it
            continue
        along = axis == "rows"                     # row codes: their edges run down camera columns
        prefix = "col" if axis == "columns" else "row"
        nb = spec.bits(axis)
        p_by_bit = np.array([fr.index[f"{prefix}_b{b}"] for b in range(nb)], np.int64)
        i_by_bit = np.array([fr.index[f"{prefix}_b{b}_inv"] for b in range(nb)], np.int64)
        weak = (read_sigmas * pair_noise(fr, int(p_by_bit[-1]), int(i_by_bit[-1]), decoded, along)
                if read_sigmas else 0.0)
        t = crossings[axis] if crossings and axis in crossings else axis_crossings(fr0, spec0, axis, code)
        if m:
            flags, after[axis] = _flag_blocks(fr0, spec0, spec, axis, code, t, decoded, (p_by_bit, i_by_bit), weak,
                                              limit, line_pairs)
            mask |= flags
            continue
        level = (unread_levels(fr, p_by_bit, i_by_bit, decoded, weak, tile) if weak and spec.xor_base is None
                 else np.zeros(fr.shape, np.int8))
        flags, res, lo, lv = _flag_axis(fr.stack, spec, axis, code, t, level, (p_by_bit, i_by_bit), weak, limit,
                                        EDGE_GAP_PX, line_pairs)
        mask |= flags
        residuals[axis] = res, lo, lv
    mask &= decoded
    mask |= decoded & (_local_share(mask, decoded, region_half) > REGION_SHARE)
    share = float(np.count_nonzero(mask)) / max(int(np.count_nonzero(decoded)), 1)
    if share > NAMED_SHARE:          # something moved: which frames
        moved += [name for names in after.values() for name in names]
        for axis, (res, lo, lv) in residuals.items():
            size = spec.width if axis == "columns" else spec.height
            nb = spec.bits(axis)
            o = _tiled_offsets(res, lo, lv, edge_bit_lut(size), nb)
            offsets[axis] = o
            prefix = "col" if axis == "columns" else "row"
            named = max(NAMED_OFFSET_CODES, 0.5 * float(o.max()))   # the bits displaced about as much as the most
            for b in range(nb - 1, -1, -1):                        # in capture order: most significant first
                if o[b] > named:
                    moved += [f"{prefix}_b{b}", f"{prefix}_b{b}_inv"]
    return MotionCheck(mask, share, tuple(sorted(moved, key=frame_order.__getitem__)), offsets, tuple(undersampled))


def unread_levels(fr: CaptureStack, p_by_bit: np.ndarray, i_by_bit: np.ndarray, decoded: np.ndarray, weak: float,
                  tile: tuple[int, int]) -> np.ndarray:
    """(H, W) int8: how many of an axis's finest bits the capture does not read around each pixel (0: it reads
    them all). In each ``tile`` (rows, columns; pixels), a bit is not read where over :data:`UNREAD_SHARE` of the
    decoded pixels have its pattern and inverse within ``weak`` grey levels (a stripe the optics blurred away, a
    dark surface): then neither it nor any finer bit is checked there. ``p_by_bit``/``i_by_bit``: each bit's
    pattern and inverse frame (bit 0 first)."""
    from rangekit.coded.motion import _kernels as M

    H, W = fr.shape
    ty, tx = max(int(tile[0]), 1), max(int(tile[1]), 1)
    counts = np.empty((-(-H // ty), -(-W // tx), len(p_by_bit) + 1), np.int64)
    M.tile_unread(fr.stack, p_by_bit, i_by_bit, decoded, np.float32(weak), ty, tx, counts)
    unread = counts[..., 1:] > UNREAD_SHARE * counts[..., :1]
    top = len(p_by_bit) - np.argmax(unread[..., ::-1], axis=-1)          # 1 + the coarsest unread bit
    levels = np.where(unread.any(axis=-1), top, 0).astype(np.int8)
    return np.repeat(np.repeat(levels, ty, axis=0), tx, axis=1)[:H, :W]


def _flag_axis(stack: np.ndarray, spec: PatternSpec, axis: str, code: np.ndarray, t: np.ndarray, level: np.ndarray,
               frames: tuple[np.ndarray, np.ndarray], weak: float, limit: float, max_gap: float, line_pairs: bool
               ) -> tuple[np.ndarray, ...]:
    """One axis's check (:func:`check_motion`): ``(flags (H, W) bool, residuals, lower codes, levels)``, the last
    three along rows of the axis's crossings (camera rows for column codes, camera columns for row codes; each
    residual in codes of its level: :func:`rangekit.coded.motion._kernels.crossing_residuals`). ``code``: (H, W)
    the axis's codes; ``t``: their crossings (:func:`rangekit.coded.binary.axis_crossings`); ``level``: (H, W) how
    many finest bits are not checked at each pixel (:func:`unread_levels`); ``frames``: each bit's pattern and
    inverse frame in ``stack`` (bit 0 first); ``weak``: grey levels; ``limit``: codes (of each level); ``max_gap``:
    camera pixels between successive edges (:data:`EDGE_GAP_PX`)."""
    from rangekit.coded.motion import _kernels as M

    along = axis == "rows"                     # row codes: their edges run down camera columns
    c2 = np.ascontiguousarray(code.T) if along else code
    t2 = np.ascontiguousarray(t.T) if along else t
    l2 = np.ascontiguousarray(level.T) if along else level
    p_by_bit, i_by_bit = frames
    nb = len(p_by_bit)
    lut = edge_bit_lut(spec.width if axis == "columns" else spec.height)
    if l2.any():
        tl = np.empty(t2.shape, np.float32)
        M.level_crossings(stack, c2, l2, t2, p_by_bit, i_by_bit, lut, along, tl)
    else:
        tl = t2
    res = np.empty(t2.shape, np.float64)
    lo = np.empty(t2.shape, np.int64)
    M.crossing_residuals(c2, l2, tl, max_gap, stack, p_by_bit, i_by_bit, lut, frame_words(nb, spec.xor_base),
                         float(weak), along, res, lo)
    lv = l2[:, :-1]
    res, limits = still_baseline(res, lo, lv, lut, nb, limit)
    flags = np.empty(c2.shape, bool)
    M.flag_bracketed(tl, res / limits[lv] if l2.any() else res, 1.0 if l2.any() else float(limits[0]), flags)
    flags = _along_stripe(flags, line_pairs)
    return (flags.T if along else flags), res, lo, lv


def _along_stripe(flags: np.ndarray, line_pairs: bool) -> np.ndarray:
    """``flags`` (lines, N) kept where the neighbouring line along the stripe is flagged too: a move displaces a
    stripe along its whole length, the noise at a stripe edge flags a pixel here and there (``line_pairs``: each
    line's neighbour is the other line of its pair)."""
    along_stripe = np.zeros_like(flags)
    if line_pairs:                                   # each line's neighbour: the other line of its pair
        n = len(flags) // 2 * 2
        along_stripe[0:n:2], along_stripe[1:n:2] = flags[1:n:2], flags[0:n:2]
    else:
        along_stripe[1:] |= flags[:-1]
        along_stripe[:-1] |= flags[1:]
    return flags & along_stripe


def _flag_blocks(fr: CaptureStack, spec: PatternSpec, blocks: PatternSpec, axis: str, code: np.ndarray,
                 t: np.ndarray, decoded: np.ndarray, frames: tuple[np.ndarray, np.ndarray], weak: float, limit: float,
                 line_pairs: bool) -> tuple[np.ndarray, list[str]]:
    """``(flags, after)``: (H, W) bool the pixels of a hybrid without its finest Gray bits bracketed by a block edge
    off the phase (:mod:`rangekit.coded.motion.blocks`), and the frames of the axis taken after a move
    (:func:`rangekit.coded.motion.blocks.frames_after`). ``fr``/``spec``: the capture; ``blocks``: its Gray code of blocks
    (:func:`rangekit.coded.binary.gray_blocks`); ``code``: (H, W) the axis's block codes; ``t``: their crossings;
    ``frames``: each block bit's pattern and inverse frame; ``weak``: grey levels (an edge whose bit changes by
    less across its pair is not checked); ``limit``: projector px."""
    from rangekit.coded.motion import _kernels as M
    from rangekit.coded.motion.blocks import edge_offsets, frames_after, offset_baseline, read_edges, wrapped_phase

    along = axis == "rows"
    tr = (lambda a: np.ascontiguousarray(a.T)) if along else (lambda a: a)
    u, period = wrapped_phase(fr, spec, axis)
    c2, t2 = tr(code), tr(t)
    lut = edge_bit_lut(blocks.width if axis == "columns" else blocks.height)
    sure, bit = read_edges(fr.stack, c2, t2, frames, lut, weak, along)
    off = edge_offsets(c2, t2, tr(u), period, 1 << spec.min_gray_bit, tr(decoded), sure, MAX_CODE_STEP)
    off, limit = offset_baseline(off, bit, len(frames[0]), limit, NOISE_SIGMAS, line_pairs)
    flags = np.empty(c2.shape, bool)
    M.flag_bracketed(t2, off, float(limit), flags)
    flags = _along_stripe(flags, line_pairs)
    flags = flags.T if along else flags
    moved = np.count_nonzero(flags & decoded) > NAMED_SHARE * max(int(np.count_nonzero(decoded)), 1)
    return flags, (frames_after(off, bit, limit, spec, axis) if moved else [])


def still_baseline(res: np.ndarray, lo: np.ndarray, level: np.ndarray, edge_bit: np.ndarray, nb: int, limit: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The residuals measured against what the capture's own optics give a still surface, and the limit its noise
    allows: ``(residuals, limits)``, ``limits`` (nb + 1,) one per level (``level``: each residual's, the finest
    bits masked off; its residual and limit are in codes of that level).

    A real projector and lens move each bit's stripe edges by their own amount (a fine stripe is blurred more,
    and a made inverse crosses its pattern off the true edge), the same over the whole image: each triple of bits
    (previous, own, next edge) has its own median residual, which is taken off (the skull of SLStudio: up to
    0.08 codes). A move displaces edges by an amount that changes sign with the surface's slope, so it barely
    moves these medians. The edges wander from row to row by the projector's noise (SLStudio's: 0.12 codes
    RMS, against 0.03 on the simulator): the limit is at least :data:`NOISE_SIGMAS` times that noise (the MAD's
    sigma, over each level's residuals). Codes that turn back (``inf``) are left as they are (those the noise
    explains are NaN already: :data:`READ_SIGMAS`)."""
    limits = np.full(nb + 1, float(limit))
    finite = np.isfinite(res)
    if not finite.any():
        return res, limits
    ys, xs = np.nonzero(finite)
    key, m = _bit_triples(lo[ys, xs], level[ys, xs], edge_bit, nb)
    r = res[ys, xs]
    order = np.argsort(key.astype(np.uint16) if key.max() < 1 << 16 else key, kind="stable")   # radix sort
    ks, rs = key[order], r[order]
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    ends = np.r_[starts[1:], len(ks)]
    medians = np.array([np.median(rs[a:b]) for a, b in zip(starts, ends)])   # one per bit triple (<= nb^3 a level)
    dev = np.empty_like(r)
    dev[order] = rs - np.repeat(medians, ends - starts)
    out = res.copy()
    out[ys, xs] = dev
    levels = np.unique(m)
    for k in levels:
        sigma = 1.4826 * float(np.median(np.abs(dev if len(levels) == 1 else dev[m == k])))
        limits[k] = max(limit, NOISE_SIGMAS * sigma)
    return out, limits


def _bit_triples(c: np.ndarray, m: np.ndarray, edge_bit: np.ndarray, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """For edges with lower codes ``c`` at levels ``m`` (their ``m`` finest bits masked off), the key of each one's
    (level, previous edge's bit, own bit, next edge's bit), and the levels as int64: the neighbouring edges of a
    level-m edge are ``1 << m`` codes away."""
    m = m.astype(np.int64)
    top = len(edge_bit) - 1
    gap = np.left_shift(1, m)
    key = ((m * nb + edge_bit[np.clip(c - gap, 0, top)]) * nb + edge_bit[c]) * nb + edge_bit[np.clip(c + gap, 0, top)]
    return key, m


def frame_words(nb: int, xor_base: int | None) -> np.ndarray:
    """(2**nb,) int64: for each code, its frame bits (bit b set: frame b brighter than its inverse), as
    :meth:`rangekit.coded.patterns.PatternSpec.frame` draws them (XOR codes: the bits above the base XORed with it)."""
    g = gray_encode(np.arange(1 << nb, dtype=np.int64))
    if xor_base is None:
        return g
    base = (g >> xor_base) & 1
    above = ~np.int64((1 << (xor_base + 1)) - 1) & ((1 << nb) - 1)
    return g ^ (above * base)


def pair_noise(fr: CaptureStack, p: int, i: int, decoded: np.ndarray, along_columns: bool) -> float:
    """The noise (grey levels, std) of a pattern minus its inverse: from the differences between neighbouring decoded
    pixels of frame pair ``p``, ``i`` (the axis's coarsest bit, whose stripes are widest: one edge a line) along the
    lines the axis's crossings run along (camera rows for column codes; ``along_columns``: camera columns, for row
    codes), every other line: a trimmed RMS (past 4x the MAD's sigma is its stripe edge, a depth edge or texture)
    over the square root of 2. Those lines are whole in :func:`rangekit.coded.motion.detect.detect_motion`'s
    stack too. SLStudio's skull 2.4 grey levels (made inverses: twice the frame's noise and the white's and
    black's), the simulator's 1.4."""
    if along_columns:
        d = fr.stack[p, :, ::2].astype(np.float32) - fr.stack[i, :, ::2].astype(np.float32)
        dd, ok = np.diff(d, axis=0), decoded[1:, ::2] & decoded[:-1, ::2]
    else:
        d = fr.stack[p, ::2].astype(np.float32) - fr.stack[i, ::2].astype(np.float32)
        dd, ok = np.diff(d, axis=1), decoded[::2, 1:] & decoded[::2, :-1]
    v = np.abs(dd[ok])
    if v.size == 0:
        return 0.0
    cap = max(4.0 * 1.4826 * float(np.median(v)), 2.0)
    v = v[v <= cap]
    return float(np.sqrt(np.mean(v * v) / 2.0))


def code_step(code: np.ndarray, decoded: np.ndarray) -> float:
    """The median step of ``code`` ((H, W) int) between neighbouring decoded pixels along its rows where it changes
    (by at most 64 codes: larger steps are depth edges): 1 where the camera resolves every code (a camera pixel or
    more per code), about the projector codes per camera pixel where it does not. 0 when nothing changes."""
    steps = np.abs(np.diff(code, axis=1))
    ok = decoded[:, 1:] & decoded[:, :-1] & (steps > 0) & (steps <= 64)
    return float(np.median(steps[ok])) if ok.any() else 0.0


def _local_share(mask: np.ndarray, decoded: np.ndarray, half: tuple[int, int]) -> np.ndarray:
    """(H, W) the share of the decoded pixels flagged in the (2 half[0] + 1) x (2 half[1] + 1) pixels around each
    pixel."""
    if not mask.any():
        return np.zeros(mask.shape)
    flagged, there = _box_sum(mask, half), _box_sum(decoded, half)
    return np.where(there > 0, flagged / np.maximum(there, 1), 0.0)


def _box_sum(a: np.ndarray, half: tuple[int, int]) -> np.ndarray:
    """(H, W) float64 count of True in the (2 half[0] + 1) x (2 half[1] + 1) pixels around each pixel (clipped at
    the borders): OpenCV's unnormalised box filter, exact for counts (17x the cumulative sums' speed at 1280x1024)."""
    import cv2

    return cv2.boxFilter(np.ascontiguousarray(a).view(np.uint8), cv2.CV_64F, (2 * half[1] + 1, 2 * half[0] + 1),
                         normalize=False, borderType=cv2.BORDER_CONSTANT)


def _tiled_offsets(res: np.ndarray, lo: np.ndarray, level: np.ndarray, edge_bit: np.ndarray, nb: int,
                   tile: int = TILE_PX) -> np.ndarray:
    """(nb,) each bit's displacement (codes, >= 0): the :data:`NAMED_PERCENTILE` th percentile over ``tile`` x
    ``tile`` pixel tiles (with at least :data:`MIN_TILE_EDGES` residuals) of the size of the bit's offset in the
    tile. A move displaces stripes by different amounts and either way across the image (with the slope of the
    surface), so the offsets are solved where they are about constant: in each tile, the mean residual of each
    (level, previous, own, next) bit triple (each residual clipped to +-1 code of its level, then in codes), then
    least squares over the triples, weighted by their counts, the most significant bit with edges at 0."""
    ys, xs = np.nonzero(np.isfinite(res))
    if len(ys) == 0:
        return np.zeros(nb)
    key, m = _bit_triples(lo[ys, xs], level[ys, xs], edge_bit, nb)
    r = np.clip(res[ys, xs], -1.0, 1.0) * np.left_shift(1, m)
    keys = (nb + 1) * nb ** 3
    tiles_x = -(-res.shape[1] // tile)
    group = ((ys // tile) * tiles_x + xs // tile) * keys + key
    groups, inverse, counts = np.unique(group, return_inverse=True, return_counts=True)
    means = np.bincount(inverse, weights=r) / counts
    tile_of, key = groups // keys, groups % nb ** 3
    prev, own, nxt = key // (nb * nb), (key // nb) % nb, key % nb
    A = np.zeros((len(groups), nb))
    np.add.at(A, (np.arange(len(groups)), own), 1.0)
    np.add.at(A, (np.arange(len(groups)), prev), -0.5)
    np.add.at(A, (np.arange(len(groups)), nxt), -0.5)
    w = np.sqrt(counts)
    starts = np.flatnonzero(np.r_[True, tile_of[1:] != tile_of[:-1]])
    stops = np.r_[starts[1:], len(groups)]
    found = []
    for s0, s1 in zip(starts, stops):
        if counts[s0:s1].sum() < MIN_TILE_EDGES:
            continue
        At = A[s0:s1] * w[s0:s1, None]
        seen = np.flatnonzero(np.any(At != 0, axis=0))
        free = seen[seen != seen.max()]
        o = np.zeros(nb)
        if len(free):
            o[free] = np.linalg.lstsq(At[:, free], means[s0:s1] * w[s0:s1], rcond=None)[0]
        found.append(np.abs(o))
    return np.percentile(found, NAMED_PERCENTILE, axis=0) if found else np.zeros(nb)
