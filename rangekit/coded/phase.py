"""Phase-shift decoding (methods ``phase`` and ``hybrid``): N-step phase, unwrapping, and the masks.

Module doc of :mod:`rangekit.coded.decode` ("Phase shifting") explains the method.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.coded.binary import axis_code
from rangekit.coded.frames import CaptureStack, row_chunks, run_parallel
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.response import PhaseCorrection

__all__ = ["phase_from_steps", "decode_phase_maps"]


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


def _decode_phase(fr: CaptureStack, spec: PatternSpec, axis: str, region, coarse: np.ndarray | None,
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



def decode_phase_maps(fr: CaptureStack, spec: PatternSpec, shadow, low, glob_mask, conf, t_low: float, fs: float,
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
            code = axis_code(fr, spec, axis, workers, chunk_rows)
            incons |= code < 0
            coarse = code.astype(np.float32)
        ph = np.empty((H, W), np.float32)
        mod = np.empty((H, W), np.float32)

        def run(rs: slice, axis=axis, coarse=coarse, ph=ph, mod=mod) -> None:
            p, m = _decode_phase(fr, spec, axis, (rs, slice(None)), None if coarse is None else coarse[rs],
                                 corrections)
            ph[rs], mod[rs] = p, m

        run_parallel(run, row_chunks(H, chunk_rows), workers)
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

