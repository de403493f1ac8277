"""The frames of the tool codecs, each value computed as the tool computes it (its float precision, its rounding).

Notation: along the coded axis (columns: ``x`` = projector column; rows: ``x`` = projector row) of ``n``
projector pixels; pixel centres at integers; ``pi_f = float32(pi)``; ``trunc`` is C++'s float-to-uchar
conversion (towards zero), ``rint`` OpenCV's ``saturate_cast<uchar>`` (nearest, ties to even). Frames are
constant along the other axis unless said otherwise. Frame names start with ``col_`` or ``row_``.

SLStudio ``pstools::computePhaseVector(n, phase, pitch)`` (``src/codec/pstools.cpp``), used by its codecs::

    v(x) = trunc(255 * float(0.5 * (1 + cosf(2 pi_f x / pitch - phase))))     (float32 argument)

``micro`` (SLStudio ``src/codec/CodecPhaseShiftMicro.cpp``; Gupta & Nayar, "Micro Phase Shifting", CVPR 2012)
    ``periods`` p_0 .. p_{F-1} (projector px; SLStudio's F = 10: 75.02, 70.00, 71.32, 72.47, 73.72, 76.23,
    77.35, 78.40, 79.22, 80.00). Frames, in order (F + 2):
    ``m0_s0 .. m0_s2``: ``computePhaseVector(n, -2 pi/3 * s, p_0)``, s = 0, 1, 2 (three steps of p_0);
    ``m1 .. m{F-1}``: ``computePhaseVector(n, pi if j odd else 0, p_j)`` (one frame per other period).
``modulated`` (SLStudio ``src/codec/CodecPhaseShiftModulated.cpp``, ``USE_SINE_MODULATOR``)
    Fringe ``L_i(x) = float(0.5 + 0.5 cosf(2 pi_f x / P - 2 pi_f i / 3))``, P = float(n) / ``n_periods`` (24, SLStudio's ``nPhaseX``
    since 2015; 8 for two days before);
    carrier across the other axis (y, of m pixels) ``M_k(y)``, the same with Q = float(m) / ``carrier_n_periods``
    (16). Frames, in order (9 + 3): ``fringe{i}_carrier{k}`` = ``rint(255 L_i(x) M_k(y))`` (``cv::multiply``
    with scale 255 to 8 bits), i outer, k inner; then ``cue_s0 .. cue_s2`` = ``computePhaseVector(n,
    2 pi/3 * s, n)`` (one period across the screen, 3 steps).
``ftp``, ``psp``, ``faps`` (OpenCV contrib ``modules/structured_light/src/sinusoidalpattern.cpp``,
``SinusoidalPattern::generate``, markers off as by default)
    Period ``P = n // n_periods`` (C integer division; OpenCV's default ``nbrOfPeriods`` 20), ``f =
    float32(1 / P)``, ``shift`` = float32(2 pi / 3) by default::

        fringe_s{i}(x) = rint(127.5 + 127.5 sin(2 pi f x + float32(i * shift)))      (double precision)

    ``psp`` and ``faps`` project OpenCV's three frames i = 0, 1, 2; ``ftp`` only the first (OpenCV's FTP
    reads its phase from frame 0; it takes three captures only for its shadow mask). With ``cue`` (the
    default), three more frames follow: the same formula with one period across the axis (``P = n``, what
    ``generate`` makes with ``nbrOfPeriods`` 1), ``cue_s0 .. cue_s2``. Spatial unwrapping leaves the
    column relative, OpenCV's markers need the fundamental matrix (its ``convertToAbsolutePhaseMap`` stops
    at the epipolar lines), so rangekit picks each pixel's period from this cue (decoding without it is
    refused).

Each axis in ``axes`` ("columns" first) gets its own frames, all of one axis after the other.
"""

from __future__ import annotations

import math

import numpy as np

from rangekit.budget import MAX_IMAGE_SIDE_PX
from rangekit.coded.codecs.option_checks import is_number, show, whole_number
from rangekit.errors import PatternError

__all__ = ["FRINGE_METHODS", "SINUS_METHODS", "SLSTUDIO_MICRO_PERIODS", "OPENCV_SHIFT", "PI_F32",
           "check_fringe_options", "fringe_frame_names", "fringe_frame", "slstudio_phase_line",
           "slstudio_shift", "slstudio_cos_line", "opencv_sine_line", "opencv_period", "modulated_pitches"]

FRINGE_METHODS = ("micro", "modulated", "ftp", "psp", "faps")
SINUS_METHODS = ("ftp", "psp", "faps")

#: SLStudio's micro phase shifting periods (projector px), the first projected in three steps.
SLSTUDIO_MICRO_PERIODS = (75.02, 70.00, 71.32, 72.47, 73.72, 76.23, 77.35, 78.40, 79.22, 80.00)
#: OpenCV SinusoidalPattern's default shift, ``(float)(2 * CV_PI / 3)``, as a Python float.
OPENCV_SHIFT = float(np.float32(2 * np.pi / 3))
#: ``const float pi = M_PI`` of SLStudio's codecs.
PI_F32 = np.float32(np.pi)
MAX_MICRO_PERIODS = 16

_DEFAULTS = {
    "micro": {"periods": list(SLSTUDIO_MICRO_PERIODS)},
    "modulated": {"n_periods": 24, "carrier_n_periods": 16},   # CodecPhaseShiftModulated.cpp nPhaseX, nPhaseY
    "ftp": {"n_periods": 20, "shift": OPENCV_SHIFT, "cue": True},
    "psp": {"n_periods": 20, "shift": OPENCV_SHIFT, "cue": True},
    "faps": {"n_periods": 20, "shift": OPENCV_SHIFT, "cue": True},
}


def check_fringe_options(method: str, options: dict, width: int, height: int, axes: tuple[str, ...]) -> dict:
    """``options`` over the method's defaults, checked against every coded axis; PatternError naming the
    option, what was expected and what was found."""
    opts = {**_DEFAULTS[method], **options}
    sizes = {"columns": width, "rows": height}
    if method == "micro":
        ps = opts["periods"]
        if not (isinstance(ps, (list, tuple)) and 2 <= len(ps) <= MAX_MICRO_PERIODS
                and all(is_number(p) and 2 <= p <= MAX_IMAGE_SIDE_PX for p in ps)):
            raise PatternError(f"micro periods must be 2 to {MAX_MICRO_PERIODS} numbers in 2..{MAX_IMAGE_SIDE_PX} "
                               f"projector px (the first projected in 3 steps), found {show(ps)}")
        opts["periods"] = [float(p) for p in ps]
    elif method == "modulated":
        for axis in axes:
            other = "rows" if axis == "columns" else "columns"
            opts["n_periods"] = whole_number(opts["n_periods"], f"modulated n_periods (fringe periods across the "
                                       f"{sizes[axis]} projector {axis})", 1, sizes[axis] // 2)
            opts["carrier_n_periods"] = whole_number(opts["carrier_n_periods"], f"modulated carrier_n_periods (carrier "
                                               f"periods across the {sizes[other]} projector {other})", 1,
                                               max(1, sizes[other] // 2))
    else:
        for axis in axes:
            opts["n_periods"] = whole_number(opts["n_periods"], f"{method} n_periods (fringe periods across the "
                                       f"{sizes[axis]} projector {axis}, each at least 2 px)", 1,
                                       max(1, sizes[axis] // 2))
        if opts["n_periods"] > 1 and min(sizes[a] for a in axes) // opts["n_periods"] < 2:
            raise PatternError(f"{method} n_periods {opts['n_periods']} leaves periods under 2 projector px")
        shift = opts["shift"]
        if not (is_number(shift) and 0.05 <= shift <= math.pi - 0.05):
            raise PatternError(f"{method} shift must be a phase step in radians within 0.05..{math.pi - 0.05:.2f} "
                               f"(OpenCV's default 2 pi / 3), found {show(shift)}")
        opts["shift"] = float(np.float32(shift))
        if not isinstance(opts["cue"], bool):
            raise PatternError(f"{method} cue must be true or false (three one-period frames that make the "
                               f"column absolute), found {show(opts['cue'])}")
    return opts


def fringe_frame_names(method: str, axes: tuple[str, ...], options: dict) -> list[str]:
    """The frame names of a fringe method, in projection order (module doc)."""
    names = []
    for axis in axes:
        p = "col" if axis == "columns" else "row"
        if method == "micro":
            names += [f"{p}_m0_s{s}" for s in range(3)] + [f"{p}_m{j}" for j in range(1, len(options["periods"]))]
        elif method == "modulated":
            names += [f"{p}_fringe{i}_carrier{k}" for i in range(3) for k in range(3)]
            names += [f"{p}_cue_s{s}" for s in range(3)]
        else:
            names += [f"{p}_fringe_s{i}" for i in range(1 if method == "ftp" else 3)]
            names += [f"{p}_cue_s{s}" for s in range(3)] if options["cue"] else []
    return names


# ------------------------------------------------------------------------------------------- the tools' lines
def slstudio_shift(s: int, n: int) -> np.float32:
    """SLStudio's step phase ``float phase = 2.0*pi/N * s`` (double arithmetic on float pi, stored as float)."""
    return np.float32(2.0 * float(PI_F32) / n * s)


def slstudio_phase_line(n: int, pitch: float, phase: float) -> np.ndarray:
    """``pstools::computePhaseVector(n, phase, pitch)`` as uint8 (n,): float32 argument, truncated (module doc)."""
    x = np.arange(n, dtype=np.float32)
    arg = (np.float32(2) * PI_F32 * x) / np.float32(pitch) - np.float32(phase)
    c = np.cos(arg.astype(np.float64)).astype(np.float32)           # cosf of a float argument
    amp = (0.5 * (np.float32(1) + c).astype(np.float64)).astype(np.float32)
    return np.floor(255.0 * amp.astype(np.float64)).astype(np.uint8)


def slstudio_cos_line(n: int, pitch: float, phase: float) -> np.ndarray:
    """``float amp = 0.5 + 0.5 * cos(2 * pi * c / pitch - phase)`` of the modulated codec, float32 (n,)."""
    x = np.arange(n, dtype=np.float32)
    arg = (np.float32(2) * PI_F32 * x) / np.float32(pitch) - np.float32(phase)
    c = np.cos(arg.astype(np.float64)).astype(np.float32)
    return (0.5 + 0.5 * c.astype(np.float64)).astype(np.float32)


def opencv_period(n: int, n_periods: int) -> int:
    """OpenCV's ``period = width / nbrOfPeriods`` (int division), projector px."""
    return n // n_periods


def opencv_sine_line(n: int, period: int, step: int, shift: float) -> np.ndarray:
    """OpenCV ``SinusoidalPattern::generate``'s row of frame ``step``, uint8 (n,) (module doc)."""
    f = np.float64(np.float32(1) / np.float32(period))
    arg = 2 * np.pi * f * np.arange(n, dtype=np.float64) + np.float64(np.float32(step) * np.float32(shift))
    return np.clip(np.rint(127.5 + 127.5 * np.sin(arg)), 0, 255).astype(np.uint8)


def modulated_pitches(options: dict, n: int, m: int) -> tuple[np.float32, np.float32]:
    """(fringe pitch P along the coded axis of n px, carrier pitch Q along the other of m px), float32."""
    return (np.float32(n) / np.float32(options["n_periods"]), np.float32(m) / np.float32(options["carrier_n_periods"]))


def _modulated(i: int, k: int, options: dict, n: int, m: int) -> np.ndarray:
    """``rint(255 L_i(x) M_k(y))``, (m, n) uint8 with x along axis 1."""
    P, Q = modulated_pitches(options, n, m)
    step = lambda j: np.float32(np.float32(2) * PI_F32 / np.float32(3) * np.float32(j))  # noqa: E731
    L = slstudio_cos_line(n, P, step(i))
    M = slstudio_cos_line(m, Q, step(k))
    return np.rint((np.float32(255) * L)[None, :] * M[:, None]).clip(0, 255).astype(np.uint8)


def fringe_frame(method: str, name: str, width: int, height: int, options: dict) -> np.ndarray:
    """Frame ``name`` of a fringe method as a (height, width) uint8 image (module doc)."""
    prefix, rest = name.split("_", 1)
    n, m = (width, height) if prefix == "col" else (height, width)
    if method == "micro":
        periods = options["periods"]
        if rest.startswith("m0_s"):
            line = slstudio_phase_line(n, periods[0], np.float32(-2.0 * float(PI_F32) / 3.0 * int(rest[4:])))
        else:
            j = int(rest[1:])
            line = slstudio_phase_line(n, periods[j], PI_F32 if j % 2 else np.float32(0.0))
    elif method == "modulated":
        if rest.startswith("cue_s"):
            line = slstudio_phase_line(n, np.float32(n), slstudio_shift(int(rest[5:]), 3))
        else:
            i, k = int(rest[6]), int(rest[-1])
            img = _modulated(i, k, options, n, m)
            return np.ascontiguousarray(img if prefix == "col" else img.T)
    else:
        cue = rest.startswith("cue_s")
        period = n if cue else opencv_period(n, options["n_periods"])
        line = opencv_sine_line(n, period, int(rest[-1]), options["shift"])
    return np.broadcast_to(line[None, :] if prefix == "col" else line[:, None], (height, width)).copy()
