"""Binary codes (Gray code and XOR codes): integer code maps and their subpixel stripe edges.

Module doc of :mod:`rangekit.coded.decode` ("Binary codes", "Subpixel Gray-code edges") explains the
method; the per-pixel work is in the compiled :mod:`rangekit.coded._kernels`.
"""

from __future__ import annotations

import math

import numpy as np

from rangekit.coded.frames import CaptureStack, row_chunks, run_parallel
from rangekit.errors import DecodeError
from rangekit.coded.patterns import PatternSpec, gray_decode, gray_encode, make_pattern_spec

__all__ = ["axis_code", "axis_crossings", "codes_beyond", "axis_subpixel", "edge_bit_lut", "gray_blocks", "gray_lut",
           "smooth_along_stripes"]


def _decode_bits(fr: CaptureStack, spec: PatternSpec, axis: str, region, need_diffs: bool):
    """Integer code of one chunk (int32, -1 where outside the projector) and, if asked or needed for
    XOR codes, the per-bit differences ``pattern - inverse`` (nb, h, w) indexed by bit."""
    prefix = "col" if axis == "columns" else "row"
    nb = spec.bits(axis)
    base = spec.xor_base
    gray = None
    diffs = None
    for b in range(nb - 1, -1, -1):  # most significant first
        P = fr.get(f"{prefix}_b{b}", region)
        I = fr.get(f"{prefix}_b{b}_inv", region)
        if gray is None:
            gray = np.zeros(P.shape, np.uint16 if nb <= 16 else np.uint32)
            if need_diffs or base is not None:
                diffs = np.empty((nb,) + P.shape, np.int16 if P.dtype == np.uint8 else np.int32)
        gray <<= 1
        gray |= P > I
        if diffs is not None:
            np.subtract(P, I, out=diffs[b], dtype=diffs.dtype)
    if base is not None and nb > base + 1:
        low_mask = gray.dtype.type((1 << (base + 1)) - 1)
        gray &= low_mask
        # Stripes of column codes cross camera rows (axis 1); stripes of row codes cross columns (axis 0).
        high = _xor_high_bits(diffs, base, axis=1 if axis == "columns" else 0)
        for i, b in enumerate(range(base + 1, nb)):
            gray |= high[i].astype(gray.dtype) << gray.dtype.type(b)
    code = gray_lut(nb)[gray]
    code[code >= (spec.width if axis == "columns" else spec.height)] = -1
    return code, diffs


def _box_along(a: np.ndarray, axis: int, half: int) -> np.ndarray:
    """Sum over a window of 2 * half + 1 samples along ``axis`` (edges: the part inside)."""
    c = np.cumsum(a, axis=axis, dtype=np.int64)
    n = a.shape[axis]
    pad = [(0, 0)] * a.ndim
    pad[axis] = (1, 0)
    c = np.pad(c, pad)
    hi = np.minimum(np.arange(n) + half + 1, n)
    lo = np.maximum(np.arange(n) - half, 0)
    return np.take(c, hi, axis=axis) - np.take(c, lo, axis=axis)


def _xor_high_bits(diffs: np.ndarray, base: int, axis: int, half: int = 2) -> np.ndarray:
    """Gray bits above the base of an XOR code, decided robustly (bool (nb - base - 1, h, w)).

    ``g_b = o_b XOR o_base`` is 1 where the frame and the base frame have opposite signs. Near a base
    edge both are weak and noisy, so the sign of the product is averaged over ``2 * half + 1`` pixels
    across the stripes: g_b never changes across a base edge, and near g_b's own edge an error only
    moves the pixel to the neighbouring column.
    """
    d_base = diffs[base].astype(np.int32)
    return np.stack([_box_along(diffs[b] * d_base, axis, half) < 0 for b in range(base + 1, len(diffs))])


_LUTS: dict[int, np.ndarray] = {}


def gray_lut(nb: int) -> np.ndarray:
    if nb not in _LUTS:
        _LUTS[nb] = gray_decode(np.arange(1 << nb)).astype(np.int32)
    return _LUTS[nb]


_EDGE_LUTS: dict[int, np.ndarray] = {}


def edge_bit_lut(size: int) -> np.ndarray:
    """For code c, the Gray bit that changes between c and c + 1 (which frame has the edge)."""
    if size not in _EDGE_LUTS:
        c = np.arange(size + 1)
        changed = gray_encode(c) ^ gray_encode(c + 1)
        _EDGE_LUTS[size] = np.log2(np.maximum(changed, 1)).astype(np.int64)
    return _EDGE_LUTS[size]


def axis_code(fr: CaptureStack, spec: PatternSpec, axis: str, workers: int, chunk_rows: int, *,
              ties: str = "zero", keep_beyond: bool = False) -> np.ndarray:
    """Integer code map of one axis: compiled Gray decoding, or chunked numpy for XOR codes; -1 where the code is
    past the projector's width (height), or for Gray codes with ``keep_beyond`` the code itself (the caller
    measures how many pixels decode past the projector, :func:`codes_beyond`). ``ties``: the bit of a pixel whose
    frame equals its inverse, "zero" (rangekit's rule, frame brighter than inverse) or "one" (Gray codes only:
    RoomAlive's ``frame >= inverse``). A hybrid without its Gray bits below ``m = spec.min_gray_bit`` gives the
    block ``code >> m`` (the Gray code's bits above m are the Gray code of ``u >> m``)."""
    from rangekit.coded import _kernels as K

    H, W = fr.shape
    prefix = "col" if axis == "columns" else "row"
    nb, m = spec.bits(axis), spec.min_gray_bit
    code = np.empty((H, W), np.int32)
    if spec.xor_base is None:
        p_idx = np.array([fr.index[f"{prefix}_b{b}"] for b in range(nb - 1, m - 1, -1)], np.int64)
        i_idx = np.array([fr.index[f"{prefix}_b{b}_inv"] for b in range(nb - 1, m - 1, -1)], np.int64)
        size = spec.width if axis == "columns" else spec.height
        limit = 1 << (nb - m) if keep_beyond else -(-size // (1 << m))
        K.gray_rows(fr.stack, p_idx, i_idx, gray_lut(nb - m), limit, code, 1 if ties == "one" else 0)
        return code
    if ties != "zero":
        raise DecodeError(f"ties={ties!r}: expected 'zero' for XOR codes ('one' is for Gray codes)")
    # XOR codes decide their high bits over windows across the stripes: rows need a halo of 2.
    halo = 2 if axis == "rows" else 0

    def run(rs: slice) -> None:
        r0, r1 = max(rs.start - halo, 0), min(rs.stop + halo, H)
        c, _ = _decode_bits(fr, spec, axis, (slice(r0, r1), slice(None)), False)
        code[rs] = c[rs.start - r0: rs.stop - r0]

    run_parallel(run, row_chunks(H, chunk_rows), workers)
    return code


def codes_beyond(code: np.ndarray, spec: PatternSpec, axis: str, counted: np.ndarray) -> tuple[int, int, int, float]:
    """(pixels of ``counted`` whose code is past the projector's width (height), the largest such code, pixels
    counted, the share of those past it whose code continues a neighbour's: within 2 of the pixel's right or lower
    neighbour): ``code`` (H, W) from :func:`axis_code` with ``keep_beyond``, set to -1 there in place. A capture
    made for a larger projector decodes a smooth map past the edge (the share near 1); frames out of order decode
    noise (near 0)."""
    beyond = code >= (spec.width if axis == "columns" else spec.height)
    seen = beyond & counted
    n = int(np.count_nonzero(seen))
    top, smooth = -1, 0.0
    if n:
        top = int(code[seen].max())
        near = np.zeros(code.shape, bool)
        near[:, :-1] |= np.abs(code[:, 1:] - code[:, :-1]) <= 2
        near[:-1, :] |= np.abs(code[1:, :] - code[:-1, :]) <= 2
        smooth = float(np.count_nonzero(near & seen)) / n
    code[beyond] = -1
    return n, top, int(np.count_nonzero(counted)), smooth


def gray_blocks(fr: CaptureStack, spec: PatternSpec) -> tuple[CaptureStack, PatternSpec]:
    """A hybrid capture without its Gray bits below ``m = spec.min_gray_bit`` as what its Gray frames are: the Gray
    code of its ``2**m`` px blocks, a ``graycode`` capture on a projector of ``ceil(W / 2**m) x ceil(H / 2**m)``
    (the Gray code's bits above m are the Gray code of ``u >> m``, :func:`axis_code`), whose bit ``b`` is the
    hybrid's bit ``b + m``: the frames white, black, then each axis's bits, are the hybrid's first frames in the same
    order (``fr.stack`` sliced, no copy). Any other capture is returned as it is."""
    m = spec.min_gray_bit
    if not m:
        return fr, spec
    blocks = make_pattern_spec("graycode", (-(-spec.width // (1 << m)), -(-spec.height // (1 << m))), axes=spec.axes)
    for axis in spec.axes:
        if blocks.bits(axis) != spec.bits(axis) - m:      # ceil(log2(ceil(n / 2**m))) = ceil(log2(n)) - m
            raise DecodeError(f"a hybrid's Gray code without its bits below {m}: {blocks.bits(axis)} block bits for "
                              f"{axis}, expected {spec.bits(axis) - m}")
    return CaptureStack(fr.stack[:blocks.n_frames], blocks, "rangekit"), blocks


def axis_crossings(fr: CaptureStack, spec: PatternSpec, axis: str, code: np.ndarray, min_bit: int = 0) -> np.ndarray:
    """Stripe-edge crossings of one axis's code map: (H, W-1) along camera rows for columns, (H-1, W) along camera
    columns for rows; float32 fraction of the way from a pixel to its neighbour where the pattern and inverse of
    the bit that changes between their codes cross, NaN where the codes do not differ by one or that bit is below
    ``min_bit`` (the finer stripes' edges left out: ``decode(..., min_edge_bit=...)``; compiled). A hybrid without
    its finest Gray bits (``code`` its blocks, :func:`axis_code`): the edges of its blocks (:func:`gray_blocks`)."""
    from rangekit.coded import _kernels as K

    if spec.min_gray_bit:
        min_bit = max(min_bit - spec.min_gray_bit, 0)
        fr, spec = gray_blocks(fr, spec)
    H, W = fr.shape
    prefix = "col" if axis == "columns" else "row"
    nb = spec.bits(axis)
    p_by_bit = np.array([fr.index[f"{prefix}_b{b}"] for b in range(nb)], np.int64)
    i_by_bit = np.array([fr.index[f"{prefix}_b{b}_inv"] for b in range(nb)], np.int64)
    edge_bit = edge_bit_lut(spec.width if axis == "columns" else spec.height)
    vertical = axis == "rows"
    t = np.empty((H - 1, W) if vertical else (H, W - 1), np.float32)
    K.crossings(fr.stack, code, p_by_bit, i_by_bit, edge_bit, vertical, t, min_bit)
    return t


def axis_subpixel(axis: str, code: np.ndarray, t: np.ndarray, max_gap: float) -> np.ndarray:
    """Subpixel stripe-edge refinement of one axis's code map from its crossings (:func:`axis_crossings`;
    compiled kernels; module doc)."""
    from rangekit.coded import _kernels as K

    out = np.empty(code.shape, np.float32)
    if axis == "columns":  # column stripes cross camera rows
        K.interp_along_rows(code, t, np.float32(max_gap), out)
    else:
        K.interp_along_cols(code, t, np.float32(max_gap), out)
    return out


def smooth_along_stripes(coord: np.ndarray, axis: str, half: int, max_step: float = 2.0) -> np.ndarray:
    """A decoded coordinate map (H, W) float32 averaged along its stripes: camera columns for projector
    columns (stripes of a column code stand about upright in the camera), camera rows for projector rows.

    Binomial weights over ``2 half + 1`` pixels (``half`` 1: 1 2 1; 2: 1 4 6 4 1, a Gaussian of 1 px; 3: 1 6 15
    20 15 6 1, of 1.22 px). A pixel keeps its value where a tap is outside the image, NaN or differs from it by
    more than ``max_step`` codes per pixel between them (a depth edge: the stripes there belong to two
    surfaces). Used where a real projector's stripe edges wander from one camera row to the next more than the
    camera's noise explains (docs/real-captures.md). One compiled pass (:func:`rangekit.coded._kernels.smooth_along`).
    """
    from rangekit.coded import _kernels as K

    if half <= 0:
        return coord
    taps = np.array([math.comb(2 * half, k) for k in range(2 * half + 1)], np.float64)
    taps /= taps.sum()
    out = np.empty(coord.shape, np.float32)
    K.smooth_along(np.ascontiguousarray(coord, dtype=np.float32), taps, float(max_step), axis == "columns", out)
    return out
