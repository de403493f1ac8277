"""Decoding micro phase shifting (Gupta & Nayar, "Micro Phase Shifting", CVPR 2012), as SLStudio projects it
(``src/codec/CodecPhaseShiftMicro.cpp``; frames in :mod:`rangekit.coded.codecs.fringes`).

Every period lies in a narrow band (SLStudio: 70-80 projector px), so defocus and global light treat all
frames alike: one offset ``a`` and one amplitude ``b`` per pixel serve every frame. The first period p_0 is
projected in three steps, each other period p_j in one frame ``0.5 + 0.5 cos(2 pi x / p_j - psi_j)``
(``psi_j`` = pi for odd j, else 0).

1. The three steps give the wrapped phase ``phi_0 = 2 pi x / p_0`` (least squares with the tool's exact
   steps, :mod:`rangekit.coded.codecs.known_shifts`; corrected for the projector's response), then ``a``
   and ``b`` of ``I = a + b g(p)`` (``g(p) = p ** gamma``, the response; least squares over the three).
2. The column is ``x = p_0 (phi_0 / 2 pi + k)``: of the candidates k inside the projector, the one whose
   predicted frames ``a + b g(0.5 + 0.5 cos(2 pi x / p_j - psi_j))`` best match the F - 1 other frames
   (least squared residual, in the camera's units, so the response needs no inversion).

SLStudio's decoder solves the F + 2 linear equations for ``a``, ``B cos phi_0``, ``B sin phi_0`` and each
``B cos phi_j`` (no response), searches every projector column for the nearest vector of cosines, and then
unwraps ``phi_0`` with that column (``pstools::unwrapWithCue`` with ``nPhases = screenCols / p_0`` cast to
an integer, which scales its columns by ``p_0 / (screenCols / floor(screenCols / p_0))``: 1.3% on a 1824 px
screen). The search over the candidates of step 2 is the same search restricted to the columns that agree
with ``phi_0``, without that scale.

Rejections: ``inconsistent`` where no candidate fits: the RMS residual per frame exceeds
``max_residual`` of ``b`` (default 0.1), or the second-best candidate is within ``min_margin`` (default
1.5x) of the best in summed squares (an ambiguous period). Shadow and low contrast from ``b``
(:mod:`rangekit.coded.codecs.fringe_result`).
"""

from __future__ import annotations

import numpy as np

from rangekit.coded.codecs.fringe_result import AxisMaps
from rangekit.coded.codecs.fringes import PI_F32
from rangekit.coded.codecs.known_shifts import corrected_phase, phase_known_shifts
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["decode_micro_axis", "MAX_RESIDUAL", "MIN_MARGIN"]

MAX_RESIDUAL = 0.1
MIN_MARGIN = 1.5
_LUT_SIZE = 4096


def _main_steps() -> np.ndarray:
    """The three steps' phases as SLStudio stores them, ``float(-2.0 * pi / 3.0 * s)``."""
    return np.array([np.float32(-2.0 * float(PI_F32) / 3.0 * s) for s in range(3)], np.float64)


def decode_micro_axis(fr: CaptureStack, spec: PatternSpec, axis: str, response: ProjectorResponse | None, *,
                      max_residual: float = MAX_RESIDUAL, min_margin: float = MIN_MARGIN) -> AxisMaps:
    """One coded axis of a ``micro`` capture: projector coordinate, signal ``b`` and the failed fits."""
    from rangekit.coded.codecs import _kernels as K

    prefix = "col" if axis == "columns" else "row"
    periods = np.array([np.float32(p) for p in spec.options["periods"]], np.float64)
    n = spec.width if axis == "columns" else spec.height
    whole = (slice(None), slice(None))
    main = [fr.get(f"{prefix}_m0_s{s}", whole) for s in range(3)]
    d = _main_steps()
    phi, _, _ = phase_known_shifts(main, d)
    phi = corrected_phase(phi, response)
    gamma = 1.0 if response is None else response.gamma
    # a, b of I = a + b g(p_s) over the three steps, p_s = 0.5 + 0.5 cos(phi - d_s).
    r = [np.power(np.float32(0.5) + np.float32(0.5) * np.cos(phi - np.float32(ds)), np.float32(gamma)) for ds in d]
    r_mean = (r[0] + r[1] + r[2]) / np.float32(3)
    i_mean = sum(m.astype(np.float32) for m in main) / np.float32(3)
    sxy = sum((ri - r_mean) * (m.astype(np.float32) - i_mean) for ri, m in zip(r, main))
    sxx = sum((ri - r_mean) ** 2 for ri in r)
    b = (sxy / np.maximum(sxx, np.float32(1e-12))).astype(np.float32)
    a = (i_mean - b * r_mean).astype(np.float32)
    J = len(periods) - 1
    e_idx = np.array([fr.index[f"{prefix}_m{j}"] for j in range(1, J + 1)], np.int64)
    psi = np.array([float(PI_F32) if j % 2 else 0.0 for j in range(1, J + 1)], np.float64)
    lut = np.linspace(0.0, 1.0, _LUT_SIZE) ** gamma
    H, W = fr.shape
    x, best, second = (np.empty((H, W), np.float32) for _ in range(3))
    K.micro_search(fr.stack, e_idx, phi, a, b, float(periods[0]), periods[0] / periods[1:], psi, lut, float(n),
                   x, best, second)
    with np.errstate(invalid="ignore", divide="ignore"):
        misfit = ~(np.sqrt(best / np.float32(J)) <= np.float32(max_residual) * b)
        ambiguous = ~(second >= np.float32(min_margin) * best)
    return AxisMaps(value=x, signal=b, reference=b, inconsistent=misfit | ambiguous | ~np.isfinite(x), white=a + b)
