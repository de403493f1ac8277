"""Decoding modulated phase shifting, as SLStudio projects it (``src/codec/CodecPhaseShiftModulated.cpp``,
``USE_SINE_MODULATOR``; frames in :mod:`rangekit.coded.codecs.fringes`).

Each of the three fringe steps ``L_i(x)`` (period P = n / ``n_periods``) is projected three times, multiplied
by a carrier ``M_k(y)`` of three steps across the other axis (period Q = m / ``carrier_n_periods``):
``I_ik = a + b L_i M_k + g_ik`` with ``g_ik`` the global light. The carrier's period is short, so the global
light hardly changes with k, and the amplitude of the carrier over k, ``D_i = b L_i / 2``, is the direct
light of fringe step i alone (Nayar et al.'s separation, done by the carrier).

1. ``D_i`` = the modulation of frames ``(i, 0), (i, 1), (i, 2)`` over the carrier's steps (SLStudio: the
   magnitude of their DFT's first bin, ``pstools::getDFTComponents``; the same up to the factor 3 / 2).
2. The fringe phase ``phi`` from ``D_0, D_1, D_2`` with steps ``2 pi i / 3`` (SLStudio: ``cv::phase(Re,
   -Im)`` of their DFT), then ``x_w = P phi / 2 pi``. Under a response ``p ** gamma``, ``D_i`` is proportional
   to ``L_i ** gamma``: the 3-step phase correction applies (:func:`rangekit.coded.response.phase_correction`).
3. The cue (three one-period steps, not modulated) gives ``x_cue = n phi_cue / 2 pi``; the period of ``x_w``
   nearest to it is taken (SLStudio: ``pstools::unwrapWithCue(up, upCue, nPhases)``, ``up *= screenCols / 2 pi``).

Masks: shadow where the cue's signal ``2 B_cue`` is below ``shadow_threshold``; low contrast where the
direct light ``b = 4 B_D`` (``B_D`` the modulation of ``D_i`` over i; under a response, ``B_D`` divided by
the modulation both fits give at their phases, :func:`rangekit.coded.codecs.known_shifts.white_minus_black`)
is below ``min_contrast`` (SLStudio thresholds the cue's DFT magnitude at 10); inconsistent where cue and
fringe disagree by more than a quarter period (:data:`rangekit.coded.codecs.fringe_result.CUE_TOLERANCE`).
``direct`` is ``b``.
"""

from __future__ import annotations

import numpy as np

from rangekit.coded.codecs.fringe_result import AxisMaps, unwrap_with_cue
from rangekit.coded.codecs.fringes import PI_F32, modulated_pitches, slstudio_shift
from rangekit.coded.codecs.known_shifts import corrected_phase, phase_known_shifts, white_minus_black
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["decode_modulated_axis"]


def _steps() -> np.ndarray:
    """SLStudio's ``float phaseX = 2 * pi / Nx * x`` (float32 arithmetic), x = 0, 1, 2."""
    return np.array([np.float32(2) * PI_F32 / np.float32(3) * np.float32(i) for i in range(3)], np.float64)


def decode_modulated_axis(fr: CaptureStack, spec: PatternSpec, axis: str, response: ProjectorResponse | None
                          ) -> AxisMaps:
    """One coded axis of a ``modulated`` capture: projector coordinate, direct light and the cue's checks."""
    prefix = "col" if axis == "columns" else "row"
    n, m = (spec.width, spec.height) if axis == "columns" else (spec.height, spec.width)
    P, _ = modulated_pitches(spec.options, n, m)
    whole = (slice(None), slice(None))
    steps = _steps()
    direct, carrier = [], []
    for i in range(3):
        psi, D, _ = phase_known_shifts([fr.get(f"{prefix}_fringe{i}_carrier{k}", whole) for k in range(3)], steps)
        direct.append(D)
        carrier.append(psi)
    phi, B_D, _ = phase_known_shifts(direct, steps)
    phi = corrected_phase(phi, response)
    # The carrier's phase from the step with the most light (the others' may be noise alone).
    brightest = np.argmax(np.stack(direct), axis=0)
    psi = corrected_phase(np.choose(brightest, carrier), response)
    cue_steps = np.array([slstudio_shift(s, 3) for s in range(3)], np.float64)
    phi_cue, B_cue, A_cue = phase_known_shifts([fr.get(f"{prefix}_cue_s{s}", whole) for s in range(3)], cue_steps)
    phi_cue = corrected_phase(phi_cue, response)
    wrapped = phi * np.float32(P / (2 * np.pi))
    value, disagree = unwrap_with_cue(wrapped, float(P), phi_cue * np.float32(n / (2 * np.pi)))
    b = white_minus_black(white_minus_black(B_D, phi, steps, response), psi, steps, response)
    return AxisMaps(value=value, signal=b, reference=np.float32(2) * B_cue, inconsistent=disagree,
                    white=A_cue + B_cue, direct=b)
