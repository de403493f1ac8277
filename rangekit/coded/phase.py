"""Phase-shift decoding (methods ``phase`` and ``hybrid``): N-step phase, unwrapping, and the masks.

Module doc of :mod:`rangekit.coded.decode` ("Phase shifting") explains the method.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.coded import _kernels as K
from rangekit.coded.binary import axis_code
from rangekit.coded.frames import CaptureStack, row_chunks, run_parallel
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.response import PhaseCorrection
from rangekit.coded.uncertainty import fit_noise_model, phase_coordinate_std

__all__ = ["phase_from_steps", "decode_phase_maps", "smooth_coordinate_map"]


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


def _stack_phase(fr: CaptureStack, idx: list[int], region) -> tuple[np.ndarray, ...]:
    """:func:`phase_from_steps` of the frames ``fr.stack[idx]`` in ``region`` (a slice of rows, all columns),
    their sums in one compiled pass (the same float32 numbers), and their alternating sum
    ``sum (-1)^s I_s`` (:func:`_noise_variance`): (phi, B, A, alt)."""
    n = len(idx)
    rows = region[0]
    h = len(range(*rows.indices(fr.shape[0])))
    S, C, A, alt = (np.empty((h, fr.shape[1]), np.float32) for _ in range(4))
    sn = np.array([np.float32(np.sin(2 * np.pi * s / n)) for s in range(n)], np.float32)
    cs = np.array([np.float32(np.cos(2 * np.pi * s / n)) for s in range(n)], np.float32)
    K.phase_sums(fr.stack, np.asarray(idx, np.int64), rows.indices(fr.shape[0])[0], sn, cs, S, C, A, alt)
    phi = np.arctan2(S, C)
    phi[phi < 0] += np.float32(2 * np.pi)
    return phi, np.float32(2.0 / n) * np.hypot(S, C), A / np.float32(n), alt


def _decode_phase(fr: CaptureStack, spec: PatternSpec, axis: str, region, coarse: np.ndarray | None,
                  corrections: dict[int, PhaseCorrection]):
    """Unwrapped projector coordinate, the weakest modulation, and the finest level's modulation B, offset
    A, noise variance estimate (:func:`_noise_variance`) and correction slope, for
    one chunk (wrapped phases mapped through ``corrections[steps]`` where given)."""
    prefix = "col" if axis == "columns" else "row"
    value = coarse
    mod_min = None
    for period, steps in spec.phase_plan(axis):
        frames = [fr.get(f"{prefix}_p{period:g}_s{s}", region) for s in range(steps)]
        phi, B, A, alt = _stack_phase(fr, [fr.index[f"{prefix}_p{period:g}_s{s}"] for s in range(steps)], region)
        slope = np.float32(1.0)
        if steps in corrections:  # PhaseCorrection's call and slope in one compiled pass, the same numbers
            phi_true, slope = np.empty_like(phi), np.empty_like(phi)
            K.phase_correct(phi, corrections[steps].offset, phi_true, slope)
        else:
            phi_true = phi
        wrapped = phi_true * np.float32(period / (2 * np.pi))
        if value is None:
            value = wrapped  # period >= size: absolute
        else:
            k = np.rint((value - wrapped) / np.float32(period))
            value = wrapped + k * np.float32(period)
        mod_min = B if mod_min is None else np.minimum(mod_min, B)
    noise = alt * alt / np.float32(steps) if steps % 2 == 0 else _noise_variance(frames, A, B, phi)
    fine = (B, A, noise, np.broadcast_to(slope, B.shape))
    return value.astype(np.float32), mod_min, fine


def _noise_variance(frames, A: np.ndarray, B: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Per-pixel estimate of the image noise variance of N phase-shifted frames (unbiased for noise of
    variance a + b I). Even N: the alternating sum ``(sum (-1)^s I_s)^2 / N``, which no harmonic below N / 2
    of the fringe reaches (a projector gamma makes harmonics 2, 3, ...; they are not noise). Odd N: the
    residual of the sinusoid fit / (N - 3), which such harmonics inflate."""
    n = len(frames)
    if n % 2 == 0:
        alt = np.zeros_like(A)
        for s, f in enumerate(frames):
            alt += f.astype(np.float32) if s % 2 == 0 else -f.astype(np.float32)
        return alt * alt / np.float32(n)
    rss = np.zeros_like(A)
    for s, f in enumerate(frames):
        rss += (f.astype(np.float32) - A - B * np.cos(phi - np.float32(2 * np.pi * s / n))) ** 2
    return rss / np.float32(max(n - 3, 1))


def decode_phase_maps(fr: CaptureStack, spec: PatternSpec, shadow, low, glob_mask, conf, t_low: float, fs: float,
                       max_disagreement: float, corrections: dict[int, PhaseCorrection], workers: int,
                       chunk_rows: int):
    """Phase and hybrid methods: unwrapped phase per axis (Gray-code coarse values for hybrid), and the
    predicted std of each decoded coordinate (:mod:`rangekit.coded.uncertainty`)."""
    H, W = fr.shape
    reject = shadow | low | glob_mask
    incons = np.zeros((H, W), bool)
    values, fines = {}, {}
    for axis in spec.axes:
        size = spec.width if axis == "columns" else spec.height
        coarse = None
        block = 1 << spec.min_gray_bit       # hybrid: projector px a Gray code names (its finest bit's)
        if spec.method == "hybrid":
            code = axis_code(fr, spec, axis, workers, chunk_rows)
            incons |= code < 0
            coarse = (code * block).astype(np.float32) + np.float32((block - 1) / 2)   # the block's centre
        ph = np.empty((H, W), np.float32)
        mod = np.empty((H, W), np.float32)
        fine = np.empty((4, H, W), np.float32)

        def run(rs: slice, axis=axis, coarse=coarse, ph=ph, mod=mod, fine=fine) -> None:
            p, m, f = _decode_phase(fr, spec, axis, (rs, slice(None)), None if coarse is None else coarse[rs],
                                    corrections)
            ph[rs], mod[rs] = p, m
            for i, a in enumerate(f):
                fine[i, rs] = a

        run_parallel(run, row_chunks(H, chunk_rows), workers)
        if coarse is not None:    # a block's centre is up to (block - 1) / 2 from its columns
            incons |= np.abs(ph - coarse) > max_disagreement + (block - 1) / 2
        incons |= (ph < -0.5) | (ph > size - 0.5)
        weak = (2 * mod < t_low) & ~shadow
        low |= weak
        reject |= weak
        conf = np.minimum(conf, np.clip(2 * mod / np.float32(fs), 0, 1))
        values[axis], fines[axis] = ph, fine
    incons &= ~reject
    ok = ~(reject | incons)
    nan = np.float32(np.nan)
    stds = _coordinate_stds(fr, spec, fines, ok, fs)
    out = []
    for axis in ("columns", "rows"):
        out += [np.where(ok, values[axis], nan) if axis in values else np.full((H, W), nan),
                np.where(ok, stds[axis], nan) if axis in stds else np.full((H, W), nan)]
    proj_col, col_std, proj_row, row_std = out
    return proj_col, proj_row, np.where(ok, conf, 0).astype(np.float32), incons, col_std, row_std


def _coordinate_stds(fr: CaptureStack, spec: PatternSpec, fines: dict, ok: np.ndarray, fs: float) -> dict:
    """Predicted std (projector pixels) of each axis's decoded coordinate: the camera noise model from the
    Gray-code pairs (hybrid) or from the finest level's frames (phase, :func:`_noise_variance`), through
    :func:`rangekit.coded.uncertainty.phase_coordinate_std`."""
    W_img = fr.get("white", (slice(None), slice(None))).astype(np.float32)
    usable = ok & (W_img < 0.98 * fs)
    step = max(1, int(np.sqrt(usable.sum() / 200000)))
    sub = (slice(None, None, step), slice(None, None, step))
    use = usable[sub]
    if spec.method == "hybrid":
        B_img = fr.get("black", sub).astype(np.float32)[use]
        L = W_img[sub][use] + B_img
        prefix = "col" if spec.axes[0] == "columns" else "row"
        n_bits, m = spec.bits(spec.axes[0]), spec.min_gray_bit
        bits = [b for b in (2, 3, 4) if m <= b < n_bits] or list(range(m, n_bits))
        D2 = np.mean([(fr.get(f"{prefix}_b{b}", sub).astype(np.float32)[use]
                       + fr.get(f"{prefix}_b{b}_inv", sub).astype(np.float32)[use] - L) ** 2 for b in bits], axis=0)
        noise = fit_noise_model(L, D2, ka=4.0, kb=2.0)
    else:
        f = next(iter(fines.values()))
        noise = fit_noise_model(f[1][sub][use], f[2][sub][use])
    out = {}
    for axis, f in fines.items():
        period, steps = spec.phase_plan(axis)[-1]
        out[axis] = phase_coordinate_std(f[0], f[1], noise, steps, period, f[3])
    return out


def smooth_coordinate_map(coord: np.ndarray, sigma_px: float) -> np.ndarray:
    """A decoded coordinate map (H, W) float32 under a Gaussian of ``sigma_px`` camera pixels, over its finite
    pixels alone (normalised convolution: a NaN neither spreads nor counts); NaN stays NaN.

    SLStudio's single-period 3-step codec blurs its column map this way (``CodecPhaseShift3.cpp``,
    ``cv::GaussianBlur(up, up, Size(0, 0), 3, 3)``) before it masks steep columns: one period across the
    screen leaves each pixel's column a few columns of noise, and without it neighbouring pixels differ by
    more than the flying-pixel filter allows. The white noise of a coordinate falls by ``2 sqrt(pi) sigma``
    (:func:`smoothed_std_factor`)."""
    import cv2

    valid = np.isfinite(coord)
    weights = cv2.GaussianBlur(valid.astype(np.float32), (0, 0), sigma_px, sigmaY=sigma_px,
                               borderType=cv2.BORDER_CONSTANT)
    total = cv2.GaussianBlur(np.where(valid, coord, 0).astype(np.float32), (0, 0), sigma_px, sigmaY=sigma_px,
                             borderType=cv2.BORDER_CONSTANT)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(valid, total / weights, np.float32(np.nan)).astype(np.float32)


def smoothed_std_factor(sigma_px: float) -> float:
    """The factor by which :func:`smooth_coordinate_map` divides the std of white noise: the Gaussian's
    weights sum to 1 and their squares to ``1 / (4 pi sigma^2)``."""
    return float(2 * np.sqrt(np.pi) * sigma_px)
