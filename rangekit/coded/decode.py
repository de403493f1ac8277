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

Predicted std of each decoded coordinate (``col_std``, ``row_std``; :mod:`rangekit.coded.uncertainty`):
phase methods from the camera noise (measured on the Gray-code pairs for hybrid, on the sinusoid fit's
alternating sum for phase) and the fringe modulation; integer Gray codes 1/sqrt(12) px; subpixel edges NaN.

Other tools' fringe codecs (micro, modulated, ftp, psp, faps) are decoded by
:func:`rangekit.coded.codecs.decoders.decode_fringes`; their module docs give each formula and its source.

Direct/global separation (Nayar et al. 2006): in the finest binary stripes half the projector is lit,
so ``direct = max - min`` and ``global = 2 (min - black)`` over the finest pattern/inverse pairs. Pixels
whose global light exceeds ``max_global_ratio`` times the direct light are rejected as
``global_dominated``.

Memory: the stack is read in chunks of rows (uint8/uint16 as captured; float32 only per chunk), on
``workers`` threads; nothing converts the whole stack.
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import DecodeError, MotionError
from rangekit.coded.binary import axis_code, axis_crossings, axis_subpixel, codes_beyond, smooth_along_stripes
from rangekit.coded.codecs.decoders import decode_fringes
from rangekit.coded.codecs.fringes import FRINGE_METHODS
from rangekit.coded.debruijn import decode_debruijn
from rangekit.coded.frames import CaptureStack
from rangekit.coded.motion import MAX_MOTION_SHARE, MOTION_LIMIT_CODES, check_motion
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.phase import decode_phase_maps, smooth_coordinate_map, smoothed_std_factor
from rangekit.coded.response import phase_correction
from rangekit.coded.result import DecodeResult
from rangekit.coded.uncertainty import GRAY_CODE_STD
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["decode"]


#: A Gray-code capture whose lit pixels decode past the projector's width (height) in more than this share was made
#: for a larger projector than the spec's (the rig's): refused, naming the extent (issue 47). A matching capture
#: has none there but misread bits: 0.24% of SLStudio's skull (skull_gray), none of RoomAlive's capture.
MAX_BEYOND_SHARE = 0.01


def refuse_codes_beyond(counts: tuple[int, int, int, float], spec: PatternSpec, axis: str) -> None:
    """DecodeError when more than :data:`MAX_BEYOND_SHARE` of the counted pixels decode past the projector in a
    smooth map (``counts`` from :func:`rangekit.coded.binary.codes_beyond`; noise past it, frames out of order, is
    left to the check of codes outside the projector)."""
    n, top, counted, smooth = counts
    if counted == 0 or n <= MAX_BEYOND_SHARE * counted or smooth < 0.5:
        return
    size = spec.width if axis == "columns" else spec.height
    raise DecodeError(f"{n / counted:.1%} of the lit pixels decode to codes outside the {spec.width}x{spec.height} "
                      f"projector the pattern set is for (projector {axis} {size}-{top}): the capture was projected at "
                      f"a larger size (at least {top + 1} {axis}; give the rig's projector the size the patterns were "
                      "made for), or its frames are in another order")


def _unchecked(asked: bool, spec: PatternSpec, moved) -> tuple[str, ...]:
    """The axes the motion check was asked for but could not check (the camera does not resolve their codes, or a
    code the check does not read), for the result to say "not checked" rather than "0%"."""
    if not asked:
        return ()
    if moved is None:
        return tuple(spec.axes)
    return tuple(moved.undersampled)


def decode(stack, spec: PatternSpec, *, order: str = "rangekit", subpixel: bool = True,
           min_contrast: float = 0.015, shadow_threshold: float = 0.01, max_global_ratio: float | None = None,
           max_gap: float = 6.0, max_disagreement: float = 1.5, full_scale: float | None = None,
           response: ProjectorResponse | None = None, stripe_smoothing: int = 0, min_edge_bit: int = 0,
           coord_smoothing: float = 0.0,
           motion: bool = False, max_motion: float | None = MAX_MOTION_SHARE, ties: str = "zero",
           workers: int = 0, chunk_rows: int = 96) -> DecodeResult:
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
        Binary codes: refine to subpixel by stripe-edge crossings (module doc; the default, as
        :func:`rangekit.coded.reconstruct.reconstruct_view` and ``rangekit decode`` without ``--integer``);
        False keeps the integer Gray code (calibration's correspondences). Phase methods are always subpixel.
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
    stripe_smoothing : int
        Subpixel edges: average each decoded coordinate along its stripes over ``2 n + 1`` pixels (binomial
        weights; :func:`rangekit.coded.binary.smooth_along_stripes`); 0, the default, leaves it per pixel. For
        captures whose stripe edges wander from row to row (a real projector's, docs/real-captures.md).
    min_edge_bit : int
        Subpixel edges: place the edges from the crossings of Gray bits ``min_edge_bit`` and up alone; a pixel
        between two of them is interpolated over the finer stripes' edges, whose bits still decide its code
        (``max_gap`` must reach across them: about ``2 ** min_edge_bit`` times the width of one code in camera
        pixels). 0, the default, uses every edge. For captures whose finest stripes cross off the coarser ones:
        a blur that is not symmetric shifts a fine, nearly sinusoidal stripe's crossing by another amount than a
        sharp edge's (SLStudio's skull: the finest bit's edges 0.19 camera pixels off the others on average, up
        to 0.5; docs/real-captures.md).
    coord_smoothing : float
        Phase methods: a Gaussian of this many camera pixels over each decoded coordinate map, over its decoded
        pixels alone (:func:`rangekit.coded.phase.smooth_coordinate_map`), as SLStudio's single-period
        3-step codec does (sigma 3); 0, the default, leaves it per pixel. The predicted stds fall by the
        factor white noise does.
    motion : binary codes (graycode, xor02, xor04): check that the object held still (:mod:`rangekit.coded.motion`):
        pixels whose code mixes frames taken before and after a move are flagged in ``motion`` and rejected. Off by
        default until the check holds on every rig (docs/coded-light.md, "Motion during a capture": it flags still
        captures of cameras that undersample the projector); ``rangekit decode`` checks.
    max_motion : the largest share of the decoded pixels that may be flagged; over it the capture is refused
        (:class:`MotionError`, naming the frames taken after the move). None: never refused.
    ties : {"zero", "one"}
        Gray codes: the bit of a pixel whose frame equals its inverse; "zero" (frame brighter than inverse) or
        "one" (frame at least its inverse: RoomAlive's rule, the ``roomalive:graycode`` layout's).
    workers, chunk_rows : threads (0: the configured number, rangekit._runtime.executor) and rows per chunk.

    The fringe codecs (micro, modulated, ftp, psp, faps) read ``min_contrast``, ``shadow_threshold``,
    ``full_scale``, ``response`` and ``workers``; the other options are the binary and phase codes'.

    Returns
    -------
    DecodeResult

    Raises
    ------
    DecodeError
        If the number of captures does not match the spec, sizes or dtypes differ, no pixel is lit
        (an all-black stack), or the captures look like another order or spec (white darker than black).
    MotionError
        (a DecodeError) If more than ``max_motion`` of the lit pixels moved during the capture.
    """
    if response is not None and not isinstance(response, ProjectorResponse):
        raise DecodeError(f"response must be a rangekit.rig.projector_response.ProjectorResponse or None, found "
                          f"{type(response).__name__} {response!r}; e.g. response=ProjectorResponse(gamma=2.2)")
    if ties not in ("zero", "one"):
        raise DecodeError(f"ties={ties!r}: expected 'zero' or 'one'")
    if isinstance(min_edge_bit, bool) or not isinstance(min_edge_bit, (int, np.integer)) or min_edge_bit < 0:
        raise DecodeError(f"min_edge_bit={min_edge_bit!r}: expected a whole number of bits >= 0")
    if spec.method in ("white", "black"):
        raise DecodeError(f"pattern {spec.method!r} carries no code; decode a graycode, xor02, xor04, phase, "
                          "hybrid, debruijn, micro, modulated, ftp, psp or faps capture")
    if spec.method == "debruijn":
        return decode_debruijn(stack, spec, min_contrast=min_contrast, shadow_threshold=shadow_threshold,
                               full_scale=full_scale)
    if spec.method in FRINGE_METHODS:
        return decode_fringes(stack, spec, order=order, min_contrast=min_contrast,
                              shadow_threshold=shadow_threshold, full_scale=full_scale, response=response,
                              workers=workers)
    from rangekit.coded import _kernels as K

    fr = CaptureStack(stack, spec, order)
    H, W = fr.shape
    fs = float(full_scale if full_scale is not None else (255 if fr.dtype == np.uint8 else 65535))
    binary = spec.method in ("graycode", "xor02", "xor04", "hybrid")
    edges = subpixel and spec.method in ("graycode", "xor02", "xor04")
    idx = fr.index
    short = [a for a in spec.axes if edges and min_edge_bit >= spec.bits(a)]
    if short:
        raise DecodeError(f"min_edge_bit={min_edge_bit}: the {short[0]} code has {spec.bits(short[0])} bits "
                          f"(0-{spec.bits(short[0]) - 1}), no stripe edge would be left")
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
    moved, beyond = None, {}
    if spec.method in ("graycode", "xor02", "xor04"):
        # Binary codes: codes, subpixel edges and the final maps all in compiled passes.
        empty_i, empty_f = np.zeros((1, 1), np.int32), np.zeros((1, 1), np.float32)
        codes, subs, cross = {}, {}, {}
        for axis in spec.axes:
            codes[axis] = axis_code(fr, spec, axis, workers, chunk_rows, ties=ties, keep_beyond=True)
            if spec.xor_base is None:
                beyond[axis] = codes_beyond(codes[axis], spec, axis, ~shadow & ~low)
            if motion or (edges and not min_edge_bit):
                cross[axis] = axis_crossings(fr, spec, axis, codes[axis])
            subs[axis] = empty_f
            if edges:
                t = cross[axis] if not min_edge_bit else axis_crossings(fr, spec, axis, codes[axis], min_edge_bit)
                subs[axis] = axis_subpixel(axis, codes[axis], t, max_gap)
        proj_col, proj_row = np.empty((H, W), np.float32), np.empty((H, W), np.float32)
        incons = np.empty((H, W), bool)
        K.finalise_binary(codes.get("columns", empty_i), subs.get("columns", empty_f), codes.get("rows", empty_i),
                          subs.get("rows", empty_f), "columns" in codes, "rows" in codes, edges, shadow, low,
                          glob_mask, conf, proj_col, proj_row, incons)
        if motion:
            moved = check_motion(fr, spec, codes, np.isfinite(proj_col), cross, MOTION_LIMIT_CODES)
            if max_motion is not None and moved.share > max_motion:
                raise MotionError(f"the object moved during the capture: {moved.describe()}; more than "
                                  f"{max_motion:.0%} moved (max_motion); capture the view again")
            proj_col[moved.mask] = np.nan
            proj_row[moved.mask] = np.nan
            conf[moved.mask] = 0.0
        if edges and stripe_smoothing > 0:
            proj_col = smooth_along_stripes(proj_col, "columns", stripe_smoothing)
            proj_row = smooth_along_stripes(proj_row, "rows", stripe_smoothing)
        # Integer codes are uniform within their stripe; subpixel edges have no noise model yet (NaN).
        std = np.float32(GRAY_CODE_STD if not edges else np.nan)
        col_std = np.where(np.isfinite(proj_col), std, np.float32(np.nan))
        row_std = np.where(np.isfinite(proj_row), std, np.float32(np.nan))
    else:
        corrections = {}
        if response is not None and not response.is_linear:
            for axis in spec.axes:
                for _, steps in spec.phase_plan(axis):
                    corrections[steps] = phase_correction(response, steps)
        proj_col, proj_row, conf, incons, col_std, row_std = decode_phase_maps(
            fr, spec, shadow, low, glob_mask, conf, min_contrast * fs, fs, max_disagreement, corrections, workers,
            chunk_rows)
        if coord_smoothing > 0:
            proj_col, proj_row = (smooth_coordinate_map(c, coord_smoothing) for c in (proj_col, proj_row))
            factor = np.float32(smoothed_std_factor(coord_smoothing))
            col_std, row_std = col_std / factor, row_std / factor
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
    for axis, counts in beyond.items():
        refuse_codes_beyond(counts, spec, axis)
    if np.count_nonzero(lit) > 100 and np.count_nonzero(incons) > 0.5 * np.count_nonzero(lit):
        raise DecodeError(f"over half of the lit pixels decode to codes outside the {spec.width}x{spec.height} "
                          "projector: the spec does not match the capture (projector size, method or order)")
    return DecodeResult(proj_col=proj_col, proj_row=proj_row, confidence=conf, shadow=shadow, low_contrast=low,
                        global_dominated=glob_mask, inconsistent=incons,
                        motion=None if moved is None or set(moved.undersampled) >= set(spec.axes) else moved.mask,
                        motion_unchecked=_unchecked(motion, spec, moved),
                        moved_frames=() if moved is None else moved.moved_frames,
                        direct=direct if binary else None, global_light=glob if binary else None,
                        white=fr.colour_white if fr.colour else w_all, col_std=col_std, row_std=row_std)

