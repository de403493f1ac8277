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

from dataclasses import dataclass, field
from typing import Callable

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
    _check_options(response, ties, min_edge_bit)
    codec = codec_of(spec.method)
    return codec(stack, spec, DecodeOptions(
        order=order, subpixel=subpixel, min_contrast=min_contrast, shadow_threshold=shadow_threshold,
        max_global_ratio=max_global_ratio, max_gap=max_gap, max_disagreement=max_disagreement, full_scale=full_scale,
        response=response, stripe_smoothing=stripe_smoothing, min_edge_bit=min_edge_bit,
        coord_smoothing=coord_smoothing, motion=motion, max_motion=max_motion, ties=ties, workers=workers,
        chunk_rows=chunk_rows))


@dataclass(frozen=True)
class DecodeOptions:
    """:func:`decode`'s keyword options, as it documents them (its signature holds their defaults), handed to a
    codec of :data:`CODECS`."""

    order: str
    subpixel: bool
    min_contrast: float
    shadow_threshold: float
    max_global_ratio: float | None
    max_gap: float
    max_disagreement: float
    full_scale: float | None
    response: ProjectorResponse | None
    stripe_smoothing: int
    min_edge_bit: int
    coord_smoothing: float
    motion: bool
    max_motion: float | None
    ties: str
    workers: int
    chunk_rows: int


#: A codec: ``codec(stack, spec, options) -> DecodeResult``, the stack and spec as :func:`decode` takes them.
Codec = Callable[[object, PatternSpec, DecodeOptions], DecodeResult]


def _check_options(response, ties: str, min_edge_bit) -> None:
    """DecodeError naming the first of ``response``, ``ties`` and ``min_edge_bit`` that :func:`decode` cannot take."""
    if response is not None and not isinstance(response, ProjectorResponse):
        raise DecodeError(f"response must be a rangekit.rig.projector_response.ProjectorResponse or None, found "
                          f"{type(response).__name__} {response!r}; e.g. response=ProjectorResponse(gamma=2.2)")
    if ties not in ("zero", "one"):
        raise DecodeError(f"ties={ties!r}: expected 'zero' or 'one'")
    if isinstance(min_edge_bit, bool) or not isinstance(min_edge_bit, (int, np.integer)) or min_edge_bit < 0:
        raise DecodeError(f"min_edge_bit={min_edge_bit!r}: expected a whole number of bits >= 0")


def codec_of(method: str) -> Codec:
    """The codec of a pattern method (:data:`CODECS`); DecodeError for a pattern that carries no code."""
    if method not in CODECS:
        raise DecodeError(f"pattern {method!r} carries no code; decode a graycode, xor02, xor04, phase, "
                          "hybrid, debruijn, micro, modulated, ftp, psp or faps capture")
    return CODECS[method]


def _decode_debruijn(stack, spec: PatternSpec, o: DecodeOptions) -> DecodeResult:
    """De Bruijn colour stripes (:func:`rangekit.coded.debruijn.decode_debruijn`)."""
    return decode_debruijn(stack, spec, min_contrast=o.min_contrast, shadow_threshold=o.shadow_threshold,
                           full_scale=o.full_scale)


def _decode_fringes(stack, spec: PatternSpec, o: DecodeOptions) -> DecodeResult:
    """Other tools' fringe codecs (:func:`rangekit.coded.codecs.decoders.decode_fringes`)."""
    return decode_fringes(stack, spec, order=o.order, min_contrast=o.min_contrast,
                          shadow_threshold=o.shadow_threshold, full_scale=o.full_scale, response=o.response,
                          workers=o.workers)


def _decode_binary(stack, spec: PatternSpec, o: DecodeOptions) -> DecodeResult:
    """Binary codes (graycode, xor02, xor04): the masks, the maps (integer or subpixel edges, the motion check),
    their plausibility."""
    fr, fs = _frames(stack, spec, o)
    short = [a for a in spec.axes if o.subpixel and o.min_edge_bit >= spec.bits(a)]
    if short:
        raise DecodeError(f"min_edge_bit={o.min_edge_bit}: the {short[0]} code has {spec.bits(short[0])} bits "
                          f"(0-{spec.bits(short[0]) - 1}), no stripe edge would be left")
    masks = _masks(fr, spec, fs, o, binary=True)
    maps = _binary_maps(fr, spec, masks, o)
    _refuse_implausible(fr, spec, fs, o, masks.shadow, maps)
    return _result(fr, spec, o, masks, maps, binary=True)


def _decode_phase(stack, spec: PatternSpec, o: DecodeOptions) -> DecodeResult:
    """Phase shifting (phase; hybrid, its periods counted by a Gray code): the masks, the unwrapped maps, their
    plausibility."""
    fr, fs = _frames(stack, spec, o)
    masks = _masks(fr, spec, fs, o, binary=spec.method == "hybrid")
    maps = _phase_maps(fr, spec, masks, fs, o)
    _refuse_implausible(fr, spec, fs, o, masks.shadow, maps)
    return _result(fr, spec, o, masks, maps, binary=spec.method == "hybrid")


#: The codec of each pattern method that carries a code (white and black carry none).
CODECS: dict[str, Codec] = {"graycode": _decode_binary, "xor02": _decode_binary, "xor04": _decode_binary,
                            "phase": _decode_phase, "hybrid": _decode_phase, "debruijn": _decode_debruijn,
                            **{m: _decode_fringes for m in FRINGE_METHODS}}


def _frames(stack, spec: PatternSpec, o: DecodeOptions) -> tuple[CaptureStack, float]:
    """The capture as :class:`CaptureStack` in ``spec``'s order, and its full scale (the largest raw value)."""
    fr = CaptureStack(stack, spec, o.order)
    return fr, float(o.full_scale if o.full_scale is not None else (255 if fr.dtype == np.uint8 else 65535))


@dataclass(frozen=True, eq=False)
class _Masks:
    """The pass over white, black and the finest stripes, each (H, W): ``confidence`` float32 in [0, 1], the
    ``shadow``, ``low`` contrast and ``global_dominated`` bool masks, the ``direct`` and ``global_light`` float32
    (fractions of full scale; zeros where the method has no plain fine stripes to separate them)."""

    confidence: np.ndarray
    shadow: np.ndarray
    low: np.ndarray
    global_dominated: np.ndarray
    direct: np.ndarray
    global_light: np.ndarray


def _masks(fr: CaptureStack, spec: PatternSpec, fs: float, o: DecodeOptions, binary: bool) -> _Masks:
    """Masks, confidence and direct/global separation (module doc) in one compiled pass; ``binary``: the method
    has Gray-code stripes to separate the light with (the method's own plain fine frames: XOR frames above the
    base are too narrow for it)."""
    from rangekit.coded import _kernels as K

    H, W = fr.shape
    idx = fr.index
    max_global_ratio = o.max_global_ratio
    if max_global_ratio is None:
        max_global_ratio = np.inf if spec.xor_base is not None else 1.0
    sep_axis = spec.axes[0]
    sep_prefix = "col" if sep_axis == "columns" else "row"
    sep_bits = [b for b in {"xor02": (0,), "xor04": (0, 1)}.get(spec.method, (1, 2))
                if binary and spec.min_gray_bit <= b < spec.bits(sep_axis)]
    sep_p = np.array([idx[f"{sep_prefix}_b{b}"] for b in sep_bits], np.int64)
    sep_i = np.array([idx[f"{sep_prefix}_b{b}_inv"] for b in sep_bits], np.int64)
    conf = np.empty((H, W), np.float32)
    shadow, low, glob_mask = (np.empty((H, W), bool) for _ in range(3))
    direct, glob = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    K.masks_rows(fr.stack, idx["white"], idx["black"], sep_p, sep_i, np.float32(o.shadow_threshold * fs),
                 np.float32(o.min_contrast * fs), np.float32(max_global_ratio), np.float32(1.0 / fs),
                 conf, shadow, low, glob_mask, direct, glob)
    return _Masks(conf, shadow, low, glob_mask, direct, glob)


@dataclass(frozen=True, eq=False)
class _Maps:
    """A codec's decoded maps, each (H, W): ``proj_col``, ``proj_row`` float32 projector pixels (NaN where not
    decoded), ``confidence`` float32, ``inconsistent`` bool, ``col_std``, ``row_std`` float32 projector pixels; the
    motion check (:func:`rangekit.coded.motion.check_motion`, None when not asked) and the counts of codes past the
    projector per axis (:func:`rangekit.coded.binary.codes_beyond`)."""

    proj_col: np.ndarray
    proj_row: np.ndarray
    confidence: np.ndarray
    inconsistent: np.ndarray
    col_std: np.ndarray
    row_std: np.ndarray
    moved: object = None
    beyond: dict = field(default_factory=dict)


def _binary_maps(fr: CaptureStack, spec: PatternSpec, masks: _Masks, o: DecodeOptions) -> _Maps:
    """Binary codes: codes, subpixel edges and the final maps all in compiled passes; the motion check (its pixels
    rejected, MotionError over ``max_motion``), the smoothing along the stripes. ``masks.confidence`` is
    completed in place."""
    from rangekit.coded import _kernels as K

    H, W = fr.shape
    edges, min_edge_bit, conf = o.subpixel, o.min_edge_bit, masks.confidence
    empty_i, empty_f = np.zeros((1, 1), np.int32), np.zeros((1, 1), np.float32)
    codes, subs, cross, beyond = {}, {}, {}, {}
    for axis in spec.axes:
        codes[axis] = axis_code(fr, spec, axis, o.workers, o.chunk_rows, ties=o.ties, keep_beyond=True)
        if spec.xor_base is None:
            beyond[axis] = codes_beyond(codes[axis], spec, axis, ~masks.shadow & ~masks.low)
        if o.motion or (edges and not min_edge_bit):
            cross[axis] = axis_crossings(fr, spec, axis, codes[axis])
        subs[axis] = empty_f
        if edges:
            t = cross[axis] if not min_edge_bit else axis_crossings(fr, spec, axis, codes[axis], min_edge_bit)
            subs[axis] = axis_subpixel(axis, codes[axis], t, o.max_gap)
    proj_col, proj_row = np.empty((H, W), np.float32), np.empty((H, W), np.float32)
    incons = np.empty((H, W), bool)
    K.finalise_binary(codes.get("columns", empty_i), subs.get("columns", empty_f), codes.get("rows", empty_i),
                      subs.get("rows", empty_f), "columns" in codes, "rows" in codes, edges, masks.shadow, masks.low,
                      masks.global_dominated, conf, proj_col, proj_row, incons)
    moved = None
    if o.motion:
        moved = check_motion(fr, spec, codes, np.isfinite(proj_col), cross, MOTION_LIMIT_CODES)
        if o.max_motion is not None and moved.share > o.max_motion:
            raise MotionError(f"the object moved during the capture: {moved.describe()}; more than "
                              f"{o.max_motion:.0%} moved (max_motion); capture the view again")
        proj_col[moved.mask] = np.nan
        proj_row[moved.mask] = np.nan
        conf[moved.mask] = 0.0
    if edges and o.stripe_smoothing > 0:
        proj_col = smooth_along_stripes(proj_col, "columns", o.stripe_smoothing)
        proj_row = smooth_along_stripes(proj_row, "rows", o.stripe_smoothing)
    # Integer codes are uniform within their stripe; subpixel edges have no noise model yet (NaN).
    std = np.float32(GRAY_CODE_STD if not edges else np.nan)
    return _Maps(proj_col, proj_row, conf, incons, np.where(np.isfinite(proj_col), std, np.float32(np.nan)),
                 np.where(np.isfinite(proj_row), std, np.float32(np.nan)), moved, beyond)


def _phase_maps(fr: CaptureStack, spec: PatternSpec, masks: _Masks, fs: float, o: DecodeOptions) -> _Maps:
    """Phase methods: each wrapped phase corrected for the projector's response, unwrapped
    (:func:`rangekit.coded.phase.decode_phase_maps`), then smoothed over ``coord_smoothing`` pixels if asked."""
    corrections = {}
    if o.response is not None and not o.response.is_linear:
        for axis in spec.axes:
            for _, steps in spec.phase_plan(axis):
                corrections[steps] = phase_correction(o.response, steps)
    proj_col, proj_row, conf, incons, col_std, row_std = decode_phase_maps(
        fr, spec, masks.shadow, masks.low, masks.global_dominated, masks.confidence, o.min_contrast * fs, fs,
        o.max_disagreement, corrections, o.workers, o.chunk_rows)
    if o.coord_smoothing > 0:
        proj_col, proj_row = (smooth_coordinate_map(c, o.coord_smoothing) for c in (proj_col, proj_row))
        factor = np.float32(smoothed_std_factor(o.coord_smoothing))
        col_std, row_std = col_std / factor, row_std / factor
    return _Maps(proj_col, proj_row, conf, incons, col_std, row_std)


def _refuse_implausible(fr: CaptureStack, spec: PatternSpec, fs: float, o: DecodeOptions, shadow: np.ndarray,
                        maps: _Maps) -> None:
    """DecodeError when the decoded capture cannot be this spec's: no pixel lit, white darker than black (another
    order), codes past the projector's extent (:func:`refuse_codes_beyond`) or over half the lit pixels
    inconsistent."""
    lit = ~shadow
    if not np.any(lit):
        raise DecodeError(f"no pixel is lit: white - black is below {o.shadow_threshold:.0%} of full scale "
                          f"({o.shadow_threshold * fs:.0f}) everywhere; was the projector on and the capture exposed?")
    H, W = fr.shape
    w_all, b_all = fr.stack[fr.index["white"]], fr.stack[fr.index["black"]]
    step = max(1, int(np.sqrt(H * W / 250000)))
    if np.mean(w_all[::step, ::step] < b_all[::step, ::step]) > 0.25:
        raise DecodeError("the white capture is darker than the black one in over 25% of the pixels: the "
                          "captures are not in this spec's order (try order='opencv') or the spec does not "
                          "match the capture")
    for axis, counts in maps.beyond.items():
        refuse_codes_beyond(counts, spec, axis)
    if np.count_nonzero(lit) > 100 and np.count_nonzero(maps.inconsistent) > 0.5 * np.count_nonzero(lit):
        raise DecodeError(f"over half of the lit pixels decode to codes outside the {spec.width}x{spec.height} "
                          "projector: the spec does not match the capture (projector size, method or order)")


def _result(fr: CaptureStack, spec: PatternSpec, o: DecodeOptions, masks: _Masks, maps: _Maps,
            binary: bool) -> DecodeResult:
    """The :class:`DecodeResult` of a binary or phase codec's masks and maps (``binary``: with the separated
    direct and global light)."""
    moved = maps.moved
    return DecodeResult(proj_col=maps.proj_col, proj_row=maps.proj_row, confidence=maps.confidence,
                        shadow=masks.shadow, low_contrast=masks.low, global_dominated=masks.global_dominated,
                        inconsistent=maps.inconsistent,
                        motion=None if moved is None or set(moved.undersampled) >= set(spec.axes) else moved.mask,
                        motion_unchecked=_unchecked(o.motion, spec, moved),
                        moved_frames=() if moved is None else moved.moved_frames,
                        direct=masks.direct if binary else None, global_light=masks.global_light if binary else None,
                        white=fr.colour_white if fr.colour else fr.stack[fr.index["white"]], col_std=maps.col_std,
                        row_std=maps.row_std)
