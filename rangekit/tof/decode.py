"""The whole continuous-wave ToF decoder: raw samples -> range, depth, points, confidence and masks."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.tof.phase import UnwrapResult, check_samples, phase_amplitude_offset, range_sigma, unwrap_ranges
from rangekit.tof.plan import C_LIGHT, FrequencyPlan
from rangekit.tof.range_maps import flying_pixels, partial_pixels, range_to_depth, range_to_points

__all__ = ["ToFResult", "decode_cw"]


@dataclass(frozen=True, eq=False)
class ToFResult:
    """A decoded continuous-wave ToF frame. Maps are (H, W) unless stated; NaN / False where invalid.

    range : float64 radial distance along each pixel's ray, metres (NaN where not ``valid``).
    depth : float64 camera-frame z, metres (NaN where not ``valid``).
    points : (N, 3) float64 world points of the valid pixels (row-major order).
    confidence : float32 in [0, 1], 0 where invalid: ``snr / (snr + 5)`` with ``snr = 1 / sigma_phi`` of
        the noisiest frequency (0.5 at 0.2 rad of phase noise).
    sigma_range : float64 predicted standard deviation of ``range``, metres.
    amplitude, offset, phase : (F, H, W) per-frequency N-bucket estimates (samples' units, radians).
    unwrap : the :class:`UnwrapResult` (wrap counts, margin, ambiguity flag).
    low_signal, ambiguous, flying, partial, valid : bool masks (each only where the ones before it are
        False); ``valid`` = none of the four and finite. ``partial``: mixed pixels at a depth edge that
        report a surface covering less than ``min_fill`` of them (:func:`partial_pixels`).
    """

    range: np.ndarray
    depth: np.ndarray
    points: np.ndarray
    confidence: np.ndarray
    sigma_range: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray
    phase: np.ndarray
    unwrap: UnwrapResult
    low_signal: np.ndarray
    ambiguous: np.ndarray
    flying: np.ndarray
    partial: np.ndarray
    valid: np.ndarray

    def __repr__(self) -> str:
        H, W = self.valid.shape
        n = H * W
        return (f"ToFResult({W}x{H}, valid={self.valid.sum() / n:.1%}, low_signal={self.low_signal.sum() / n:.1%}, "
                f"ambiguous={self.ambiguous.sum() / n:.1%}, flying={self.flying.sum() / n:.1%}, "
                f"partial={self.partial.sum() / n:.1%})")


def decode_cw(samples, plan: FrequencyPlan, camera: PinholeCamera, *, electrons_per_unit: float = 1.0,
              read_noise_e: float = 0.0, max_range: float | None = None, min_snr: float = 3.0,
              min_margin: float = 2.0, flying_angle: float | None = math.radians(15.0),
              saturation: float | None = None, min_fill: float | None = 0.5) -> ToFResult:
    """Raw CW samples -> range, depth, points, confidence and masks (the whole ToF decoder).

    Parameters
    ----------
    samples : (K, H, W) raw correlation samples, frequency-major as ``plan`` orders them, linear.
    plan : FrequencyPlan. camera : the ToF camera (its size must match the samples).
    electrons_per_unit, read_noise_e : sensor gain (electrons per sample unit, e.g. per DN) and read
        noise (electrons RMS): they set the noise model that weights the frequencies and the confidence.
    max_range : metres, default the plan's unambiguous range.
    min_snr : a pixel whose noisiest frequency has ``A / sigma_s * sqrt(N / 2) < min_snr`` (i.e. phase
        noise above ``1 / min_snr`` rad) is ``low_signal``.
    min_margin : see :func:`unwrap_ranges`.
    flying_angle : radians, threshold of :func:`flying_pixels` (default 15 degrees); None disables the
        filter.
    saturation : sample value at which the sensor clips; pixels with any sample at or above it are
        ``low_signal`` (their phase is biased). None: no check.
    min_fill : threshold of :func:`partial_pixels` (default 0.5: the reported surface covers less than half
        the pixel); None disables the filter.
    """
    S = check_samples(samples, plan, "decode_cw")
    if S.shape[1:] != (camera.height, camera.width):
        raise InputError(f"decode_cw: samples are {S.shape[2]}x{S.shape[1]} but camera {camera.name!r} is "
                         f"{camera.width}x{camera.height}")
    if not (electrons_per_unit > 0 and read_noise_e >= 0):
        raise InputError(f"decode_cw: need electrons_per_unit > 0 and read_noise_e >= 0, found "
                         f"{electrons_per_unit!r}, {read_noise_e!r}")
    maps = phase_amplitude_offset(S, plan)
    sigma = range_sigma(maps.amplitude, maps.offset, plan, electrons_per_unit=electrons_per_unit,
                        read_noise_e=read_noise_e)
    sigma_phi = sigma * (4 * np.pi * np.asarray(plan.frequencies).reshape(-1, 1, 1)) / C_LIGHT
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = 1.0 / np.nanmax(sigma_phi, axis=0)
    snr = np.nan_to_num(snr, nan=0.0, posinf=0.0)
    low = ~(snr >= min_snr)
    if saturation is not None:
        low |= (S >= saturation).any(axis=0)
    phase = np.where(low[None], np.nan, maps.phase)
    with np.errstate(divide="ignore"):
        weights = np.where(low[None], 1.0, 1.0 / sigma ** 2)
    un = unwrap_ranges(phase, plan, weights=weights, max_range=max_range, min_margin=min_margin)
    with np.errstate(divide="ignore"):
        sigma_comb = 1.0 / np.sqrt(weights.sum(axis=0))
    r = un.range
    flying = (flying_pixels(r, camera, max_angle=flying_angle) if flying_angle is not None
              else np.zeros(r.shape, bool))
    partial = (partial_pixels(r, maps.amplitude, min_fill=min_fill) if min_fill is not None
               else np.zeros(r.shape, bool))
    valid = np.isfinite(r) & ~low & ~un.ambiguous & ~flying & ~partial
    r_valid = np.where(valid, r, np.nan)
    depth = range_to_depth(r_valid, camera)
    pts = range_to_points(r_valid, camera, frame="world")[valid]
    conf = np.where(valid, snr / (snr + 5.0), 0.0).astype(np.float32)
    return ToFResult(range=r_valid, depth=depth, points=pts, confidence=conf,
                     sigma_range=np.where(valid, sigma_comb, np.nan), amplitude=maps.amplitude,
                     offset=maps.offset, phase=maps.phase, unwrap=un, low_signal=low,
                     ambiguous=un.ambiguous & ~low, flying=flying & ~low & ~un.ambiguous,
                     partial=partial & ~low & ~un.ambiguous & ~flying, valid=valid)
