"""Decode a capture stack into per-pixel projector coordinates, with confidence and rejection masks.

Fusiello ch. 13.2. Every method returns :class:`DecodeResult`: ``proj_col`` (and ``proj_row`` where the
rows are coded) as float32 projector pixels (centres at integers, NaN where invalid), a confidence in
[0, 1], and the masks that explain each rejection.

How each method decodes
-----------------------
Binary codes (graycode, xor02, xor04): each bit is the sign of ``pattern - inverse``, which does not
depend on albedo or shading. XOR codes are undone by XORing every coarse bit with the base bit. The Gray
code is turned into a binary column by a look-up table.

Subpixel Gray-code edges (``subpixel=True``): between neighbouring camera pixels whose columns differ by
one, exactly one Gray bit changes; its pattern and inverse cross at the stripe edge, projector coordinate
``c + 0.5``. Linear interpolation of ``pattern - inverse`` between the two pixels places that crossing to
a fraction of a camera pixel. Columns are then interpolated along the camera row between the crossings
on either side of each pixel (rows are done the same way along camera columns). Pixels without edges
on both sides within ``max_gap`` pixels, or whose edges disagree with their code, are rejected as
``inconsistent`` (mixing in integer values would spoil the accuracy the caller asked for).

Phase shifting (phase, hybrid): N-step phase ``atan2(sum I_s sin d_s, sum I_s cos d_s)``, ``d_s = 2 pi s
/ N``. Multi-frequency ``phase`` unwraps each period with the next coarser one; ``hybrid`` unwraps with the
Gray-code column (the Gray code gives the period, the phase the position in it) and flags pixels where
the two disagree by more than ``max_disagreement`` columns. Under a projector response ``p ** gamma``
(``response``) the measured phase is a fixed, known function of the true phase; each wrapped phase is
mapped back through :func:`rangekit.coded.response.phase_correction` before unwrapping.

Direct/global separation (Nayar et al. 2006): in the finest binary stripes half the projector is lit,
so ``direct = max - min`` and ``global = 2 (min - black)`` over the finest pattern/inverse pairs. Pixels
whose global light exceeds ``max_global_ratio`` times the direct light are rejected as
``global_dominated``.

Memory: the stack is read in chunks of rows (uint8/uint16 as captured; float32 only per chunk), on
``workers`` threads; nothing converts the whole stack.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from rangekit.errors import DecodeError
from rangekit.coded.patterns import PatternSpec, gray_decode, gray_encode
from rangekit.coded.response import PhaseCorrection, ProjectorResponse, phase_correction

__all__ = ["DecodeResult", "decode", "phase_from_steps"]


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Per-pixel projector coordinates of a capture, (H, W) maps in camera pixels."""

    proj_col: np.ndarray          # (H, W) float32 projector column u, NaN where invalid
    proj_row: np.ndarray          # (H, W) float32 projector row v, NaN where invalid or rows not coded
    confidence: np.ndarray        # (H, W) float32 in [0, 1]; 0 where invalid; higher is better
    shadow: np.ndarray            # (H, W) bool: white - black below shadow_threshold (projector light absent)
    low_contrast: np.ndarray      # (H, W) bool: lit, but the code's contrast is below min_contrast
    global_dominated: np.ndarray  # (H, W) bool: separated global light > max_global_ratio * direct light
    inconsistent: np.ndarray      # (H, W) bool: code outside the projector, code and phase disagree, or
                                  # (subpixel) no stripe edge on both sides
    direct: np.ndarray | None = None        # (H, W) float32 direct light, fraction of full scale
    global_light: np.ndarray | None = None  # (H, W) float32 global light, fraction of full scale
    white: np.ndarray | None = None         # (H, W[, 3]) the white capture, for colour

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: a projector column was decoded."""
        return np.isfinite(self.proj_col)

    def __repr__(self) -> str:
        n = self.proj_col.size
        return (f"DecodeResult({self.proj_col.shape[1]}x{self.proj_col.shape[0]}, valid={self.valid.sum() / n:.1%}, "
                f"shadow={self.shadow.sum() / n:.1%}, low_contrast={self.low_contrast.sum() / n:.1%}, "
                f"global={self.global_dominated.sum() / n:.1%}, inconsistent={self.inconsistent.sum() / n:.1%})")


# --------------------------------------------------------------------------- stack access
class _Frames:
    """The capture stack as one (K, H, W) array with frame indices by name (colour converted to grey)."""

    def __init__(self, stack, spec: PatternSpec, order: str) -> None:
        names = spec.frame_names_in(order)
        if isinstance(stack, np.ndarray):
            if stack.ndim not in (3, 4):
                raise DecodeError(f"the capture stack must be (K, H, W) or (K, H, W, 3), found shape {stack.shape}")
            frames = stack
        else:
            frames = [np.asarray(f) for f in stack]
        if len(frames) != len(names):
            raise DecodeError(f"found {len(frames)} captures, pattern {spec.method!r} on a {spec.width}x{spec.height} "
                              f"projector needs {len(names)} ({', '.join(names[:4])}{', ...' if len(names) > 4 else ''})")
        shape0, dtype0 = frames[0].shape, frames[0].dtype
        if not isinstance(frames, np.ndarray):
            for i, f in enumerate(frames):
                if f.shape != shape0:
                    raise DecodeError(f"capture {i} has shape {f.shape}, capture 0 has {shape0}; all captures must "
                                      "have the same size")
                if f.dtype != dtype0:
                    raise DecodeError(f"capture {i} is {f.dtype}, capture 0 is {dtype0}; mixed bit depths")
        if dtype0 not in (np.uint8, np.uint16):
            raise DecodeError(f"captures have dtype {dtype0}; expected uint8 or uint16 raw captures")
        if len(shape0) not in (2, 3) or (len(shape0) == 3 and shape0[2] != 3):
            raise DecodeError(f"captures must be (H, W) grey or (H, W, 3) RGB images, found {shape0}")
        self.colour = len(shape0) == 3
        self.colour_white = frames[names.index("white")] if "white" in names else None
        if self.colour:  # grey = mean of RGB, in the captures' own dtype
            frames = [(np.asarray(f).sum(axis=2, dtype=np.uint32) // 3).astype(dtype0) for f in frames]
        if isinstance(frames, np.ndarray):
            self.stack = np.ascontiguousarray(frames)
        else:
            self.stack = np.stack(frames)  # one copy; pass a (K, H, W) array to avoid it
        self.index = {n: i for i, n in enumerate(names)}
        self.shape = shape0[:2]
        self.dtype = dtype0

    def get(self, name: str, region: tuple[slice, slice]) -> np.ndarray:
        return self.stack[self.index[name]][region]


def _chunks(n: int, size: int) -> list[slice]:
    return [slice(i, min(i + size, n)) for i in range(0, n, size)]


# --------------------------------------------------------------------------- binary codes
def _decode_bits(fr: _Frames, spec: PatternSpec, axis: str, region, need_diffs: bool):
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
    code = _gray_lut(nb)[gray]
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


def _gray_lut(nb: int) -> np.ndarray:
    if nb not in _LUTS:
        _LUTS[nb] = gray_decode(np.arange(1 << nb)).astype(np.int32)
    return _LUTS[nb]


_EDGE_LUTS: dict[int, np.ndarray] = {}


def _edge_bit_lut(size: int) -> np.ndarray:
    """For code c, the Gray bit that changes between c and c + 1 (which frame has the edge)."""
    if size not in _EDGE_LUTS:
        c = np.arange(size + 1)
        changed = gray_encode(c) ^ gray_encode(c + 1)
        _EDGE_LUTS[size] = np.log2(np.maximum(changed, 1)).astype(np.int64)
    return _EDGE_LUTS[size]


# --------------------------------------------------------------------------- phase
def phase_from_steps(frames: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """N-step phase shifting: (phase in [0, 2 pi), modulation B, offset A) as float32.

    ``frames[s] = A + B cos(phi - 2 pi s / N)``, N = len(frames) >= 3.
    """
    n = len(frames)
    S = np.zeros(frames[0].shape, np.float32)
    C = np.zeros(frames[0].shape, np.float32)
    A = np.zeros(frames[0].shape, np.float32)
    for s, f in enumerate(frames):
        f32 = f.astype(np.float32)
        S += np.float32(np.sin(2 * np.pi * s / n)) * f32
        C += np.float32(np.cos(2 * np.pi * s / n)) * f32
        A += f32
    phi = np.arctan2(S, C)
    phi[phi < 0] += np.float32(2 * np.pi)
    return phi, np.float32(2.0 / n) * np.hypot(S, C), A / np.float32(n)


def _decode_phase(fr: _Frames, spec: PatternSpec, axis: str, region, coarse: np.ndarray | None,
                  corrections: dict[int, PhaseCorrection]):
    """Unwrapped projector coordinate and the weakest modulation for one chunk (wrapped phases mapped
    through ``corrections[steps]`` where given)."""
    prefix = "col" if axis == "columns" else "row"
    value = coarse
    mod_min = None
    for period, steps in spec.phase_plan(axis):
        frames = [fr.get(f"{prefix}_p{period:g}_s{s}", region) for s in range(steps)]
        phi, B, _ = phase_from_steps(frames)
        if steps in corrections:
            phi = corrections[steps](phi)
        wrapped = phi * np.float32(period / (2 * np.pi))
        if value is None:
            value = wrapped  # period >= size: absolute
        else:
            k = np.rint((value - wrapped) / np.float32(period))
            value = wrapped + k * np.float32(period)
        mod_min = B if mod_min is None else np.minimum(mod_min, B)
    return value.astype(np.float32), mod_min


# --------------------------------------------------------------------------- driver
def decode(stack, spec: PatternSpec, *, order: str = "rangekit", subpixel: bool = False,
           min_contrast: float = 0.015, shadow_threshold: float = 0.01, max_global_ratio: float | None = None,
           max_gap: float = 6.0, max_disagreement: float = 1.5, full_scale: float | None = None,
           response: ProjectorResponse | None = None, workers: int = 2, chunk_rows: int = 96) -> DecodeResult:
    """Decode a capture stack into projector coordinates.

    Parameters
    ----------
    stack : (K, H, W) or (K, H, W, 3) uint8/uint16 ndarray, or a sequence of K such images
        Raw captures in ``spec``'s frame order (or OpenCV's with ``order="opencv"``). Read chunk by
        chunk in its own dtype; never converted to float as a whole.
    spec : PatternSpec
        What was projected.
    order : {"rangekit", "opencv"}
        Capture order; "opencv" is GrayCodePattern's (column pairs, row pairs, white, black).
    subpixel : bool
        Binary codes: refine to subpixel by stripe-edge crossings (module doc). Phase methods are always
        subpixel.
    min_contrast : float
        Reject pixels whose code contrast (white - black for binary codes; 2x modulation for phase) is
        below this fraction of full scale.
    shadow_threshold : float
        Pixels with white - black below this fraction of full scale are in the projector's shadow.
    max_global_ratio : float, optional
        Reject pixels whose separated global light exceeds this multiple of their direct light. Default
        1 for Gray code (its coarse bits fail there); no limit for XOR codes, which are built to tolerate
        global light and whose narrow stripes make the separation itself unreliable under defocus.
    max_gap : float
        Subpixel: largest distance in camera pixels between the two stripe edges bracketing a pixel.
    max_disagreement : float
        Hybrid: largest |phase - Gray code| in projector pixels before a pixel is inconsistent.
    full_scale : float, optional
        Largest raw value (default 255 for uint8, 65535 for uint16; give 4095 for 12-bit data).
    response : ProjectorResponse, optional
        The projector's response (the rig file's ``projector_response``). Phase methods correct each
        wrapped phase for it (:func:`rangekit.coded.response.phase_correction`); None or gamma 1 changes
        nothing. Binary codes do not depend on it.
    workers, chunk_rows : threads and rows per chunk.

    Returns
    -------
    DecodeResult

    Raises
    ------
    DecodeError
        If the number of captures does not match the spec, sizes or dtypes differ, no pixel is lit
        (an all-black stack), or the captures look like another order or spec (white darker than black).
    """
    if response is not None and not isinstance(response, ProjectorResponse):
        raise DecodeError(f"response must be a rangekit.coded.response.ProjectorResponse or None, found "
                          f"{type(response).__name__} {response!r}; e.g. response=ProjectorResponse(gamma=2.2)")
    if spec.method in ("white", "black"):
        raise DecodeError(f"pattern {spec.method!r} carries no code; decode a graycode, xor02, xor04, phase, "
                          "hybrid or debruijn capture")
    if spec.method == "debruijn":
        from rangekit.coded.debruijn import decode_debruijn

        return decode_debruijn(stack, spec, min_contrast=min_contrast, shadow_threshold=shadow_threshold,
                               full_scale=full_scale)
    from rangekit.coded import _kernels as K

    fr = _Frames(stack, spec, order)
    H, W = fr.shape
    fs = float(full_scale if full_scale is not None else (255 if fr.dtype == np.uint8 else 65535))
    binary = spec.method in ("graycode", "xor02", "xor04", "hybrid")
    edges = subpixel and spec.method in ("graycode", "xor02", "xor04")
    idx = fr.index
    if max_global_ratio is None:
        max_global_ratio = np.inf if spec.xor_base is not None else 1.0

    # Masks, confidence and direct/global separation: one pass over white, black and the finest stripes
    # (the method's own plain fine frames: XOR frames above the base are too narrow for it).
    sep_axis = spec.axes[0]
    sep_prefix = "col" if sep_axis == "columns" else "row"
    sep_bits = [b for b in {"xor02": (0,), "xor04": (0, 1)}.get(spec.method, (1, 2))
                if binary and b < spec.bits(sep_axis)]
    sep_p = np.array([idx[f"{sep_prefix}_b{b}"] for b in sep_bits], np.int64)
    sep_i = np.array([idx[f"{sep_prefix}_b{b}_inv"] for b in sep_bits], np.int64)
    conf = np.empty((H, W), np.float32)
    shadow, low, glob_mask = (np.empty((H, W), bool) for _ in range(3))
    direct, glob = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    K.masks_rows(fr.stack, idx["white"], idx["black"], sep_p, sep_i, np.float32(shadow_threshold * fs),
                 np.float32(min_contrast * fs), np.float32(max_global_ratio), np.float32(1.0 / fs),
                 conf, shadow, low, glob_mask, direct, glob)
    if spec.method in ("graycode", "xor02", "xor04"):
        # Binary codes: codes, subpixel edges and the final maps all in compiled passes.
        empty_i, empty_f = np.zeros((1, 1), np.int32), np.zeros((1, 1), np.float32)
        codes, subs = {}, {}
        for axis in spec.axes:
            codes[axis] = _axis_code(fr, spec, axis, workers, chunk_rows)
            subs[axis] = _axis_subpixel(fr, spec, axis, codes[axis], max_gap) if edges else empty_f
        proj_col, proj_row = np.empty((H, W), np.float32), np.empty((H, W), np.float32)
        incons = np.empty((H, W), bool)
        K.finalise_binary(codes.get("columns", empty_i), subs.get("columns", empty_f), codes.get("rows", empty_i),
                          subs.get("rows", empty_f), "columns" in codes, "rows" in codes, edges, shadow, low,
                          glob_mask, conf, proj_col, proj_row, incons)
    else:
        corrections = {}
        if response is not None and not response.is_linear:
            for axis in spec.axes:
                for _, steps in spec.phase_plan(axis):
                    corrections[steps] = phase_correction(response, steps)
        proj_col, proj_row, conf, incons = _decode_phase_maps(
            fr, spec, shadow, low, glob_mask, conf, min_contrast * fs, fs, max_disagreement, corrections, workers,
            chunk_rows)
    lit = ~shadow
    if not np.any(lit):
        raise DecodeError(f"no pixel is lit: white - black is below {shadow_threshold:.0%} of full scale "
                          f"({shadow_threshold * fs:.0f}) everywhere; was the projector on and the capture exposed?")
    w_all, b_all = fr.stack[idx["white"]], fr.stack[idx["black"]]
    step = max(1, int(np.sqrt(H * W / 250000)))
    if np.mean(w_all[::step, ::step] < b_all[::step, ::step]) > 0.25:
        raise DecodeError("the white capture is darker than the black one in over 25% of the pixels: the "
                          "captures are not in this spec's order (try order='opencv') or the spec does not "
                          "match the capture")
    if np.count_nonzero(lit) > 100 and np.count_nonzero(incons) > 0.5 * np.count_nonzero(lit):
        raise DecodeError(f"over half of the lit pixels decode to codes outside the {spec.width}x{spec.height} "
                          "projector: the spec does not match the capture (projector size, method or order)")
    return DecodeResult(proj_col=proj_col, proj_row=proj_row, confidence=conf, shadow=shadow, low_contrast=low,
                        global_dominated=glob_mask, inconsistent=incons,
                        direct=direct if binary else None, global_light=glob if binary else None,
                        white=fr.colour_white if fr.colour else w_all)


def _decode_phase_maps(fr: _Frames, spec: PatternSpec, shadow, low, glob_mask, conf, t_low: float, fs: float,
                       max_disagreement: float, corrections: dict[int, PhaseCorrection], workers: int,
                       chunk_rows: int):
    """Phase and hybrid methods: unwrapped phase per axis (Gray-code coarse values for hybrid)."""
    H, W = fr.shape
    reject = shadow | low | glob_mask
    incons = np.zeros((H, W), bool)
    values = {}
    for axis in spec.axes:
        size = spec.width if axis == "columns" else spec.height
        coarse = None
        if spec.method == "hybrid":
            code = _axis_code(fr, spec, axis, workers, chunk_rows)
            incons |= code < 0
            coarse = code.astype(np.float32)
        ph = np.empty((H, W), np.float32)
        mod = np.empty((H, W), np.float32)

        def run(rs: slice, axis=axis, coarse=coarse, ph=ph, mod=mod) -> None:
            p, m = _decode_phase(fr, spec, axis, (rs, slice(None)), None if coarse is None else coarse[rs],
                                 corrections)
            ph[rs], mod[rs] = p, m

        _parallel(run, _chunks(H, chunk_rows), workers)
        if coarse is not None:
            incons |= np.abs(ph - coarse) > max_disagreement
        incons |= (ph < -0.5) | (ph > size - 0.5)
        weak = (2 * mod < t_low) & ~shadow
        low |= weak
        reject |= weak
        conf = np.minimum(conf, np.clip(2 * mod / np.float32(fs), 0, 1))
        values[axis] = ph
    incons &= ~reject
    ok = ~(reject | incons)
    nan = np.float32(np.nan)
    proj_col = np.where(ok, values["columns"], nan) if "columns" in values else np.full((H, W), nan)
    proj_row = np.where(ok, values["rows"], nan) if "rows" in values else np.full((H, W), nan)
    return proj_col, proj_row, np.where(ok, conf, 0).astype(np.float32), incons


def _axis_code(fr: _Frames, spec: PatternSpec, axis: str, workers: int, chunk_rows: int) -> np.ndarray:
    """Integer code map of one axis: compiled Gray decoding, or chunked numpy for XOR codes."""
    from rangekit.coded import _kernels as K

    H, W = fr.shape
    prefix = "col" if axis == "columns" else "row"
    nb = spec.bits(axis)
    code = np.empty((H, W), np.int32)
    if spec.xor_base is None:
        p_idx = np.array([fr.index[f"{prefix}_b{b}"] for b in range(nb - 1, -1, -1)], np.int64)
        i_idx = np.array([fr.index[f"{prefix}_b{b}_inv"] for b in range(nb - 1, -1, -1)], np.int64)
        K.gray_rows(fr.stack, p_idx, i_idx, _gray_lut(nb), spec.width if axis == "columns" else spec.height, code)
        return code
    # XOR codes decide their high bits over windows across the stripes: rows need a halo of 2.
    halo = 2 if axis == "rows" else 0

    def run(rs: slice) -> None:
        r0, r1 = max(rs.start - halo, 0), min(rs.stop + halo, H)
        c, _ = _decode_bits(fr, spec, axis, (slice(r0, r1), slice(None)), False)
        code[rs] = c[rs.start - r0: rs.stop - r0]

    _parallel(run, _chunks(H, chunk_rows), workers)
    return code


def _axis_subpixel(fr: _Frames, spec: PatternSpec, axis: str, code: np.ndarray, max_gap: float) -> np.ndarray:
    """Subpixel stripe-edge refinement of one axis's code map (compiled kernels; module doc)."""
    from rangekit.coded import _kernels as K

    H, W = fr.shape
    prefix = "col" if axis == "columns" else "row"
    nb = spec.bits(axis)
    p_by_bit = np.array([fr.index[f"{prefix}_b{b}"] for b in range(nb)], np.int64)
    i_by_bit = np.array([fr.index[f"{prefix}_b{b}_inv"] for b in range(nb)], np.int64)
    edge_bit = _edge_bit_lut(spec.width if axis == "columns" else spec.height)
    out = np.empty((H, W), np.float32)
    if axis == "columns":  # column stripes cross camera rows
        t = np.empty((H, W - 1), np.float32)
        K.crossings(fr.stack, code, p_by_bit, i_by_bit, edge_bit, False, t)
        K.interp_along_rows(code, t, np.float32(max_gap), out)
    else:
        t = np.empty((H - 1, W), np.float32)
        K.crossings(fr.stack, code, p_by_bit, i_by_bit, edge_bit, True, t)
        K.interp_along_cols(code, t, np.float32(max_gap), out)
    return out


def _parallel(fn, items, workers: int) -> None:
    if workers <= 1:
        for it in items:
            fn(it)
        return
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for _ in pool.map(fn, items):
            pass
