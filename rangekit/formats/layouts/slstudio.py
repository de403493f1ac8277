"""SLStudio's capture folders (github jakobwilm/slstudio): ``frameSeq_NN.bmp``, one folder per scan, the frame
order of each codec's encoder (``src/codec/Codec*.cpp``; docs/real-captures.md has the frame tables).

- ``slstudio:graycode`` (``CodecGrayCode``, columns): 00 white, 01 black, then 10 frames: the 10 most significant
  bits of the ``ceil(log2(columns))``-bit reflected Gray code of the screen column, most significant first.
  No inverses: a bit is 1 where the frame is nearer white than black (:class:`~.layout.Inverse`). Those 10
  bits are the Gray code of ``column // 2**k``, ``k = ceil(log2(columns)) - 10``: a 1824-column screen is
  coded in blocks of 2 columns (``blocks``).
- ``slstudio:2x3`` (``CodecPhaseShift2x3``, columns): 00-02 three steps of 16 periods across the screen,
  03-05 three steps of one period (the cue), each ``(1 + cos(2 pi x / pitch - 2 pi k / 3)) / 2``:
  rangekit's ``phase`` method with periods (width, width / 16) and 3 steps each; no white or black frame.
- ``slstudio:3ps`` (``CodecPhaseShift3``, columns): 00-02 three steps of one period across the screen (the
  encoder adds noise of 5% to each frame): ``phase`` with the one period; no white or black frame; the
  decoded column blurred as its decoder blurs it (Gaussian, sigma 3 px).
- ``slstudio:micro`` (``CodecPhaseShiftMicro``) and ``slstudio:modulated`` (``CodecPhaseShiftModulated``),
  00-11: rangekit's ``micro`` and ``modulated`` methods, whose frames are SLStudio's in its order
  (:mod:`rangekit.coded.codecs.fringes`; modulated: 24 fringe periods, ``nPhaseX``).

Read at SLStudio's commit f49eec5 (``CodecPhaseShiftModulated.cpp``, ``CodecPhaseShiftMicro.cpp``), 9e0bc5e
(``CodecPhaseShift3.cpp``), 16df99b (``CodecGrayCode.cpp``), and e7c4246 (the example data's).
"""

from __future__ import annotations

import math

from rangekit.coded.patterns import PatternSpec
from rangekit.errors import ConfigError
from rangekit.formats.layouts.layout import BLACK_FROM_STEPS, WHITE_FROM_STEPS, AxisBlocks, CaptureLayout, Inverse

__all__ = ["SLSTUDIO_LAYOUTS"]

FRAME_FILE = "frameSeq_{:02d}.bmp"
GRAY_BITS = 10          # CodecGrayCode.cpp: Nhorz, the column bits projected whatever the screen's width

#: How rangekit reconstructs SLStudio's Gray code, each setting measured on its skull capture against the
#: authors' cloud (tests/formats/test_capture_layouts.py, docs/real-captures.md):
#: - no direct/global separation (``max_global_ratio`` inf): it needs true inverses; with made ones a blurred
#:   stripe reads as global light, and rejected 53% of the pixels the authors kept (eye sockets, rims);
#: - ``min_edge_bit`` 1 with ``max_gap`` 12: the edges placed from bits 1 and up alone (bit 0 still decides
#:   the code). The finest stripes (2 codes, 3.5 camera pixels wide) cross 0.19 camera pixels off the coarser
#:   bits' edges on average, up to 0.5 in parts of the skull, the same way at rising and falling edges: the
#:   cloud zigzagged from one edge to the next along each row. The authors keep the coarser bits' edges alone
#:   too. Median distance to their cloud 0.032 -> 0.023 mm, to the 2x3's 0.086 -> 0.062 mm; ``max_gap`` 12
#:   (twice the default, as the edges are twice as far apart): with 6 the pixels where they are over 6 px
#:   apart kept their integer code (roughness 1.12x the authors' instead of 1.005x at smoothing 2);
#: - ``stripe_smoothing`` 3 (1 6 15 20 15 6 1 along the stripes, a Gaussian of 1.22 camera pixels): the
#:   edges of bits 1 and up wander from row to row by 0.17-0.23 camera pixels RMS (their second differences
#:   down the stripes), more than the camera's noise moves a crossing (its 2x3 phase noise gives 1.5 DN);
#:   roughness 0.98x the authors' (2: 1.005x; 4: 0.96x, median 0.023 mm);
#: - ``min_confidence`` 0.015 (the decoder's own ``min_contrast``; 3.8 DN of white - black, 2.5 times the
#:   camera's noise): 0.03, tuned on the simulator's camera, drops 2% of the skull the authors kept.
#: ``benchmarks/coded/skull_choices.py`` measures each.
GRAY_VIEW_OPTIONS = {"decode_options": {"max_global_ratio": float("inf"), "min_edge_bit": 1, "max_gap": 12.0,
                                        "stripe_smoothing": 3},
                     "min_confidence": 0.015}

#: And its phase codecs (the same measurement): ``min_confidence`` 0.015 as above, and ``edge_margin`` 0:
#: three steps leave 0.6 projector columns of noise (as its 1.5 DN camera noise predicts), at low modulation
#: a single pixel then jumps in range, and the margin grows each such pixel into a 5 x 5 hole. 2x3: 91.8% of
#: the authors' points are within 0.5 mm of the cloud with the margin, 95.7% without; modulated: 72.5% and
#: 86.5% (median 0.086 and 0.051 mm).
PHASE_VIEW_OPTIONS = {"min_confidence": 0.015, "edge_margin": 0}

#: Its single-period 3-step codec: SLStudio blurs the decoded column (``CodecPhaseShift3.cpp``: Gaussian,
#: sigma 3 px) before masking, and so does rangekit here (``coord_smoothing``): one period across 1824
#: columns leaves neighbouring pixels about 6 columns apart, and without it the flying-pixel filter kept no
#: point of the skull; with it 35.8% of the authors' points lie within 0.5 mm, median 0.72 mm (SLStudio's own
#: decoder, ported: 35.9%, 0.72 mm).
PHASE_3PS_VIEW_OPTIONS = {**PHASE_VIEW_OPTIONS, "decode_options": {"coord_smoothing": 3.0}}


def _gray_blocks(width: int, height: int) -> tuple[AxisBlocks, AxisBlocks]:
    if width <= 2 ** (GRAY_BITS - 1):
        raise ConfigError(f"slstudio:graycode codes {GRAY_BITS} column bits: the projector needs more than "
                          f"{2 ** (GRAY_BITS - 1)} columns, found {width}")
    return AxisBlocks(2 ** max(0, math.ceil(math.log2(width)) - GRAY_BITS)), AxisBlocks()


def _gray_frames(width: int, height: int) -> tuple:
    pairs = []
    for k in range(GRAY_BITS):                     # file 2 + k holds bit GRAY_BITS - 1 - k of the coded column
        pairs += [2 + k, Inverse(2 + k)]
    return (0, 1, *pairs)


def _same_order(spec):
    """A spec whose frames are the tool's files in order."""
    return lambda w, h: tuple(range(spec(w, h).n_frames))


def _micro(w: int, h: int) -> PatternSpec:
    return PatternSpec("micro", w, h, ("columns",))


def _modulated(w: int, h: int) -> PatternSpec:
    return PatternSpec("modulated", w, h, ("columns",))


SLSTUDIO_LAYOUTS = {
    "slstudio:graycode": CaptureLayout(
        "slstudio:graycode", "slstudio src/codec/CodecGrayCode.cpp", FRAME_FILE, lambda w, h: 2 + GRAY_BITS,
        lambda w, h: PatternSpec("graycode", w, h, ("columns",)), _gray_frames, blocks=_gray_blocks,
        view_options=GRAY_VIEW_OPTIONS),
    "slstudio:2x3": CaptureLayout(
        "slstudio:2x3", "slstudio src/codec/CodecPhaseShift2x3.cpp, pstools.cpp", FRAME_FILE, lambda w, h: 6,
        lambda w, h: PatternSpec("phase", w, h, ("columns",),
                                 {"steps": 3, "fine_steps": 3, "periods": [w, w / 16], "rounding": "down"}),
        lambda w, h: (WHITE_FROM_STEPS, BLACK_FROM_STEPS, 3, 4, 5, 0, 1, 2), (3, 4, 5),
        view_options=PHASE_VIEW_OPTIONS),
    "slstudio:3ps": CaptureLayout(
        "slstudio:3ps", "slstudio src/codec/CodecPhaseShift3.cpp", FRAME_FILE, lambda w, h: 3,
        lambda w, h: PatternSpec("phase", w, h, ("columns",), {"periods": [w], "fine_steps": 3, "rounding": "down"}),
        lambda w, h: (WHITE_FROM_STEPS, BLACK_FROM_STEPS, 0, 1, 2), (0, 1, 2), view_options=PHASE_3PS_VIEW_OPTIONS),
    "slstudio:micro": CaptureLayout(
        "slstudio:micro", "slstudio src/codec/CodecPhaseShiftMicro.cpp", FRAME_FILE,
        lambda w, h: _micro(w, h).n_frames, _micro, _same_order(_micro)),
    "slstudio:modulated": CaptureLayout(
        "slstudio:modulated", "slstudio src/codec/CodecPhaseShiftModulated.cpp", FRAME_FILE,
        lambda w, h: _modulated(w, h).n_frames, _modulated, _same_order(_modulated), view_options=PHASE_VIEW_OPTIONS),
}


# ------------------------------------------------------------------ slstudio:calibration
#: ``CodecCalibration.cpp``'s ``nPhases``: fringes across the screen in the fine steps of each axis.
CALIBRATION_PHASES = 16


def _calibration_spec(width: int, height: int) -> PatternSpec:
    """Both axes as SLStudio's calibration codec codes them: a cue of one period and 16 periods, 3 steps each,
    the frames truncated as ``pstools::computePhaseVector`` makes them (``rounding`` "down")."""
    periods = {"columns": [width, width / CALIBRATION_PHASES], "rows": [height, height / CALIBRATION_PHASES]}
    return PatternSpec("phase", width, height, ("columns", "rows"),
                       {"steps": 3, "fine_steps": 3, "periods": periods, "rounding": "down"})


SLSTUDIO_LAYOUTS["slstudio:calibration"] = CaptureLayout(
    "slstudio:calibration", "slstudio src/codec/CodecCalibration.cpp, pstools.cpp; src/calibrator/CalibratorLocHom.cpp",
    FRAME_FILE, lambda w, h: 12, _calibration_spec,
    lambda w, h: (WHITE_FROM_STEPS, BLACK_FROM_STEPS, 3, 4, 5, 0, 1, 2, 9, 10, 11, 6, 7, 8), (3, 4, 5))
