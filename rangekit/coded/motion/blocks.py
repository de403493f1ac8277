"""The motion check of a hybrid without its finest Gray bits (``min_bit``): each Gray block edge against the phase.

A hybrid with ``min_bit`` m projects the Gray code of ``2**m`` px blocks (:func:`rangekit.coded.binary.gray_blocks`)
and then the phase frames, whose wrapped phase is decoded at every pixel. Both name the same projector column: a
block edge between blocks ``a`` and ``a + 1`` is projector column ``X = (a + 1) 2**m - 1/2`` (pixel centres), and
the phase, read at the camera point where that edge's pattern and inverse cross
(:func:`rangekit.coded.binary.axis_crossings`: between camera pixels x and x+1, the fraction t of the way),
measures where the camera point is in projector columns. On a still object the two agree up to the noise, whatever
the surface's shape: the edge and the phase are read at the same camera point. Where the object moved between the
frames of the edge's bit and the phase frames, the phase there is of another surface point: the edge is off by
the move in projector pixels,

    offset = u(t) - X,    u(t) = u_x + t (u_{x+1} - u_x)     u: the phase's projector column, unwrapped about X

(:func:`edge_offsets`; within a phase period either way: a move of a whole period is the only one not seen, and a
move displaces surfaces by different amounts with their slope). This replaced the check of the blocks' edge
spacing (:func:`rangekit.coded.motion.check.check_motion` on the codes alone), which assumes the projector column
runs linearly over two blocks (about 22 camera pixels on the default rig): on the still upright Stanford bunny its
bumps bent it by over 0.3 projector px at 28% of the column edges, and 4.2-9.7% of a view was flagged (measured
on 6 views: no codes turning back, every flag such a residual, the bunny's lit bumps and creases, not its
silhouette or the dark table).

A move between a bit's frames and the phase frames is seen at that bit's edges; the frames of this check are those
of every Gray bit and the phase: a knock anywhere from the axis's first Gray bit to the end of its phase frames
(the rows' Gray frames lie between the columns' Gray and phase frames) displaces some of them.

Checked only where the camera resolves the projector's columns: where they step by more than
:data:`rangekit.coded.motion.check.MAX_CODE_STEP` across the edge's pixel pair (a surface turned away from the
camera), the offsets' noise grows past the limit (the still bunny's column edges: 0.04 px sigma where a camera
pixel spans under 1 projector px, 0.09 at 1-1.5, 0.23 at 1.5-2, 0.43 at 2-3, 0.79 beyond; 1.4% of a view flagged
with them, mostly along its sides turned away), the rule the whole axis has (:func:`rangekit.coded.motion.check.
code_step`) applied edge by edge. And only where the phase is of one surface around the edge: the projector column's step across the edge
pixel pair agrees with the steps before and after it (:data:`MAX_STEP_CHANGE`; a depth edge or a silhouette
mixes two surfaces, a move does not, as the phase frames come from one pose), and where the edge's bit is read
(its pattern - inverse changes by at least ``weak`` across the pair: located to better than ``sqrt(2) / 6`` of
a camera pixel). Each bit's median offset is taken off up to :data:`MAX_BIT_BIAS_SHARE` of the limit (a real
projector's stripe edge sits off the phase by its own amount, :func:`rangekit.coded.motion.check.still_baseline`'s
reason), and the limit is :data:`rangekit.coded.motion.check.MOTION_LIMIT_CODES` projector px, at least
NOISE_SIGMAS times the offsets' noise along the stripe (:func:`offset_baseline`).
"""

from __future__ import annotations

import numpy as np

from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec

__all__ = ["MAX_BIT_BIAS_SHARE", "MAX_STEP_CHANGE", "MIN_BIT_EDGES", "edge_offsets", "frames_after", "offset_baseline",
           "read_edges", "wrapped_phase"]

#: The projector column's step across an edge's pixel pair may differ from the mean of the steps on either side by
#: at most this (projector px, plus half that mean step): past it the pair spans a depth edge (two surfaces). A
#: still surface's steps change by the curvature (about 0.01 px a pixel on the bunny's bumps) and the phase
#: noise (about 0.05 px).
MAX_STEP_CHANGE = 0.5
#: Each bit's median offset is taken off up to this share of the limit: a real projector's stripe edges sit off
#: the true edge by their own amount (SLStudio's skull: up to 0.08 codes, :func:`rangekit.coded.motion.check.
#: still_baseline`); a bit's edges displaced by more over most of the image (a large object moved about evenly)
#: are a move, not the projector's.
MAX_BIT_BIAS_SHARE = 0.5
#: A block bit with fewer checked edges than this says nothing of when the move came (:func:`frames_after`).
MIN_BIT_EDGES = 50


def wrapped_phase(fr: CaptureStack, spec: PatternSpec, axis: str) -> tuple[np.ndarray, float]:
    """``(u, period)``: (H, W) float64 the finest phase's projector coordinate of ``axis`` modulo its period, in
    ``[0, period)`` projector px (pixel centres: ``0.5 + 0.5 cos(2 pi u / T - 2 pi s / N)``,
    :meth:`rangekit.coded.patterns.PatternSpec.frame`), from the capture's phase frames."""
    prefix = "col" if axis == "columns" else "row"
    period, steps = spec.phase_plan(axis)[-1]
    S = np.zeros(fr.shape, np.float64)
    C = np.zeros(fr.shape, np.float64)
    for s in range(steps):
        f = fr.stack[fr.index[f"{prefix}_p{period:g}_s{s}"]]
        f = f.astype(np.float64) if f.ndim == 2 else f.astype(np.float64).mean(axis=-1)
        S += np.sin(2 * np.pi * s / steps) * f
        C += np.cos(2 * np.pi * s / steps) * f
    return np.mod(np.arctan2(S, C) * (period / (2 * np.pi)), period), float(period)


def edge_offsets(code: np.ndarray, t: np.ndarray, u: np.ndarray, period: float, block: int, decoded: np.ndarray,
                 sure: np.ndarray, max_step: float) -> np.ndarray:
    """(lines, crossings) float64: each block edge's offset from the phase (projector px, module doc), NaN where
    no edge is checked. All along lines (camera rows for column codes; the row codes' maps transposed): ``code``
    (L, N) int block codes (-1 invalid); ``t`` (L, N-1) crossings (NaN: none); ``u`` (L, N) :func:`wrapped_phase`
    modulo ``period``; ``block``: projector px a block (``2**m``); ``decoded`` (L, N) bool; ``sure`` (L, N-1)
    bool: the edge's bit is read across the pair (located better than the noise); ``max_step``: an edge where the
    projector column steps by more than this (px) across its pair is not checked (the camera undersamples the
    projector there: :data:`rangekit.coded.motion.check.MAX_CODE_STEP`)."""
    L, N = code.shape
    out = np.full((L, N - 1), np.nan)
    ys, xs = np.nonzero(np.isfinite(t) & sure)
    inner = (xs >= 1) & (xs <= N - 3)
    ys, xs = ys[inner], xs[inner]
    a, b = code[ys, xs], code[ys, xs + 1]
    ok = (a >= 0) & (b >= 0) & (np.abs(a - b) == 1)
    for k in (-1, 0, 1, 2):
        ok &= decoded[ys, xs + k]
    ys, xs, a, b = ys[ok], xs[ok], a[ok], b[ok]
    X = np.maximum(a, b).astype(np.float64) * block - 0.5          # the edge's projector column

    def near(v: np.ndarray, ref: np.ndarray) -> np.ndarray:        # v unwrapped to within half a period of ref
        return v + period * np.rint((ref - v) / period)

    u0 = near(u[ys, xs], X)
    u1 = near(u[ys, xs + 1], u0)
    um = near(u[ys, xs - 1], u0)
    up = near(u[ys, xs + 2], u1)
    step, around = u1 - u0, 0.5 * ((u0 - um) + (up - u1))
    smooth = (np.abs(step - around) <= MAX_STEP_CHANGE + 0.5 * np.abs(around)) & (np.abs(step) <= max_step)
    tt = t[ys, xs].astype(np.float64)
    off = u0 + tt * step - X
    off = off - period * np.rint(off / period)
    out[ys[smooth], xs[smooth]] = off[smooth]
    return out


def read_edges(stack: np.ndarray, code: np.ndarray, t: np.ndarray, frames: tuple[np.ndarray, np.ndarray],
               edge_bit: np.ndarray, weak: float, transposed: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(sure, bit)``, each (L, N-1) along lines as :func:`edge_offsets`'s: ``sure`` where a crossing's bit (of the
    blocks) changes its pattern - inverse by at least ``weak`` grey levels across its pixel pair (located to better
    than the noise lets: sqrt(2) / 6 of a pixel at ``weak`` = 6 noise sigmas), ``bit`` that bit (-1: no crossing).
    ``stack`` (K, H, W) the capture (the lines are its rows, or its columns: ``transposed``); ``frames``: each block
    bit's pattern and inverse frame; ``edge_bit``: the bit that changes between block codes c and c+1."""
    p_by_bit, i_by_bit = frames
    sure = np.zeros(t.shape, bool)
    bit = np.full(t.shape, -1, np.int64)
    ys, xs = np.nonzero(np.isfinite(t))
    a, b = code[ys, xs], code[ys, xs + 1]
    ok = (a >= 0) & (b >= 0) & (np.abs(a - b) == 1)
    ys, xs = ys[ok], xs[ok]
    k = edge_bit[np.minimum(a[ok], b[ok])]
    rows, cols = (xs, ys) if transposed else (ys, xs)
    step = (0, 1) if transposed else (1, 0)

    def diff(r, c):
        return stack[p_by_bit[k], r, c].astype(np.float32) - stack[i_by_bit[k], r, c].astype(np.float32)

    slope = diff(rows + step[1], cols + step[0]) - diff(rows, cols)
    sure[ys, xs] = np.abs(slope) >= weak
    bit[ys, xs] = k
    return sure, bit


def offset_baseline(off: np.ndarray, bit: np.ndarray, nb: int, limit: float, noise_sigmas: float, line_pairs: bool
                    ) -> tuple[np.ndarray, float]:
    """``(offsets, limit)``: :func:`edge_offsets`'s ``off`` (lines, crossings) with each block bit's median offset
    taken off (at most :data:`MAX_BIT_BIAS_SHARE` of ``limit`` either way), and the limit (projector px) at least
    ``noise_sigmas`` times the offsets' noise: the MAD's sigma of the difference between an edge's offset and the
    same edge's (crossing the same pixel pair) on the neighbouring line along the stripe, over sqrt(2). A move
    displaces a stripe along its length, so it does not raise that noise as it would the offsets' own spread
    (``line_pairs``: each line's neighbour is the other line of its pair). ``bit``: each crossing's block bit;
    ``nb``: the block bits."""
    ok = np.isfinite(off)
    if not ok.any():
        return off, limit
    b, v = bit[ok], off[ok]
    cap = MAX_BIT_BIAS_SHARE * limit
    medians = np.array([np.clip(np.median(v[b == k]), -cap, cap) if np.any(b == k) else 0.0 for k in range(nb)])
    out = off.copy()
    out[ok] = v - medians[b]
    first, second = (out[0::2], out[1::2]) if line_pairs else (out[:-1], out[1:])
    n = min(len(first), len(second))
    d = np.abs(first[:n] - second[:n])
    d = d[np.isfinite(d)]
    if d.size:
        limit = max(limit, noise_sigmas * 1.4826 * float(np.median(d)) / np.sqrt(2.0))
    return out, limit


def frames_after(off: np.ndarray, bit: np.ndarray, limit: float, spec: PatternSpec, axis: str) -> list[str]:
    """The frames of ``axis`` taken after a move (call it where the axis's pixels moved), from which block bits'
    edges are off the phase: ``x_k`` of each bit's ``n_k`` checked edges over ``limit`` (:func:`offset_baseline`'s
    offsets ``off``; ``bit`` each crossing's block bit; bits with under :data:`MIN_BIT_EDGES` edges left out). The
    bits are captured most significant first and the phase frames last, and a move splits them once: the bits
    before it are off the phase at one rate, those after it at a lower one (the noise's). The split is the one of
    most binomial likelihood, kept only where it gains more than BIC's ``ln(sum n) / 2`` over one rate for every
    bit (then the move came after the Gray frames). Returned: the bits after the split and the axis's phase frames.
    ``spec``: the hybrid (its bit ``b + min_gray_bit`` is block bit b). Where the phase period spans more than two
    blocks, an edge's column modulo the period depends on the next bits too, so a move of over a block puts the
    edges of the bits after it off the phase as well, and only the later frames are named (the small rig's 4 px
    blocks, 16 px period, a 2 mm knock from col_b2: the phase frames); the default rig's 8 px blocks and 16 px
    period name each bit after a 0.5 mm knock."""
    ok = np.isfinite(off)
    m, prefix = spec.min_gray_bit, ("col" if axis == "columns" else "row")
    nb = spec.bits(axis) - m
    n = np.bincount(bit[ok], minlength=nb)[:nb].astype(np.float64)
    x = np.bincount(bit[ok], weights=np.abs(off[ok]) > limit, minlength=nb)[:nb]
    order = [k for k in range(nb - 1, -1, -1) if n[k] >= MIN_BIT_EDGES]      # capture order
    xs, ns = x[order], n[order]

    def loglik(xx: np.ndarray, nn: np.ndarray) -> float:
        p = min(max(xx.sum() / max(nn.sum(), 1.0), 1e-9), 1 - 1e-9)
        return float(xx.sum() * np.log(p) + (nn.sum() - xx.sum()) * np.log(1 - p))

    best, split = loglik(xs, ns) + 0.5 * np.log(max(ns.sum(), 2.0)), len(order)
    for j in range(1, len(order)):
        before, after = xs[:j].sum() / ns[:j].sum(), xs[j:].sum() / ns[j:].sum()
        if after < before:
            ll = loglik(xs[:j], ns[:j]) + loglik(xs[j:], ns[j:])
            if ll > best:
                best, split = ll, j
    period, steps = spec.phase_plan(axis)[-1]
    return ([f"{prefix}_b{k + m}{inv}" for k in order[split:] for inv in ("", "_inv")]
            + [f"{prefix}_p{period:g}_s{s}" for s in range(steps)])
