"""Continuous-wave ToF per pixel: N-bucket phase, amplitude and offset, their noise, and multi-frequency
unwrapping into one radial range (module doc of :mod:`rangekit.tof`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError
from rangekit.tof.plan import C_LIGHT, FrequencyPlan

__all__ = ["PhaseMaps", "UnwrapResult", "phase_amplitude_offset", "phase_to_range", "range_sigma", "unwrap_ranges"]


@dataclass(frozen=True, eq=False)
class PhaseMaps:
    """Per-frequency N-bucket estimates, each (F, H, W) float64 in the samples' units (phase in radians).

    phase : in [0, 2 pi), the delay ``phi = 4 pi f r / c`` modulo 2 pi.
    amplitude : ``A`` (>= 0). offset : ``B``.
    """

    phase: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray


def check_samples(samples, plan: FrequencyPlan, where: str) -> np.ndarray:
    if not isinstance(plan, FrequencyPlan):
        raise InputError(f"{where}: plan must be a FrequencyPlan, found {type(plan).__name__}")
    S = np.asarray(samples)
    if S.ndim != 3:
        raise InputError(f"{where}: samples must be a (K, H, W) stack, found shape {S.shape}")
    if S.shape[0] != plan.n_samples:
        raise InputError(f"{where}: the frequency plan ({plan.describe()}) needs {plan.n_samples} raw samples, "
                         f"found {S.shape[0]}")
    if not (np.issubdtype(S.dtype, np.integer) or np.issubdtype(S.dtype, np.floating)):
        raise InputError(f"{where}: samples must be numeric, found dtype {S.dtype}")
    return S


def phase_amplitude_offset(samples, plan: FrequencyPlan) -> PhaseMaps:
    """Phase, amplitude and offset of every frequency from raw correlation samples.

    Parameters
    ----------
    samples : (K, H, W) with ``K = plan.n_samples``, frequency-major, linear in light (any numeric dtype).
    plan : the frequencies and phase steps the samples were taken at.

    Least squares on ``S_k = B + a cos(theta_k) + b sin(theta_k)`` (exact N-bucket formulas for equally
    spaced steps, and valid for any >= 3 distinct steps); ``phi = atan2(b, a)``, ``A = hypot(a, b)``.
    """
    S = check_samples(samples, plan, "phase_amplitude_offset")
    H, W = S.shape[1:]
    F = len(plan.frequencies)
    phase, amp, off = (np.empty((F, H, W)) for _ in range(3))
    for j, (sl, theta) in enumerate(zip(plan.slices(), plan.steps)):
        t = np.asarray(theta)
        M = np.column_stack([np.ones_like(t), np.cos(t), np.sin(t)])  # (N, 3)
        P = np.linalg.pinv(M)                                         # (3, N)
        coef = np.tensordot(P, S[sl].astype(np.float64), axes=(1, 0))  # (3, H, W)
        off[j] = coef[0]
        amp[j] = np.hypot(coef[1], coef[2])
        phase[j] = np.mod(np.arctan2(coef[2], coef[1]), 2 * np.pi)
    return PhaseMaps(phase=phase, amplitude=amp, offset=off)


def phase_to_range(phase: np.ndarray, frequency: float) -> np.ndarray:
    """Wrapped radial distance ``phi c / (4 pi f)`` in metres, in ``[0, c / (2 f))``."""
    return np.asarray(phase, dtype=np.float64) * C_LIGHT / (4 * np.pi * float(frequency))


def range_sigma(amplitude, offset, plan: FrequencyPlan, *, electrons_per_unit: float = 1.0,
                read_noise_e: float = 0.0) -> np.ndarray:
    """(F, H, W) predicted standard deviation of each frequency's range, metres.

    ``sigma_s^2 = B / g + (read_noise_e / g)^2`` per sample in the samples' units, where ``g`` is
    ``electrons_per_unit`` (shot noise: the variance in electrons equals the signal in electrons);
    ``sigma_phi = sqrt(2 / N) sigma_s / A``; ``sigma_r = c sigma_phi / (4 pi f)``. Exact to first order
    for equally spaced steps and a weak modulation (``A << B``); it is what the unwrapping weights use.
    """
    A = np.asarray(amplitude, dtype=np.float64)
    B = np.asarray(offset, dtype=np.float64)
    g = float(electrons_per_unit)
    var_s = np.maximum(B, 0.0) / g + (float(read_noise_e) / g) ** 2
    n = np.array([len(s) for s in plan.steps], dtype=np.float64).reshape((-1,) + (1,) * (A.ndim - 1))
    f = np.asarray(plan.frequencies).reshape(n.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma_phi = np.sqrt(2.0 / n * var_s) / A
    return C_LIGHT * sigma_phi / (4 * np.pi * f)


# ---------------------------------------------------------------------------------------------- unwrapping
@dataclass(frozen=True, eq=False)
class UnwrapResult:
    """Multi-frequency phase unwrapping, per pixel.

    range : (H, W) float64 metres, the inverse-variance weighted mean of the unwrapped per-frequency
        ranges; NaN where the input was NaN.
    wraps : (F, H, W) int32 wrap count ``n_j`` of each frequency (-1 where NaN).
    residual : (H, W) float64 weighted squared disagreement of the chosen candidate (chi-square with
        F - 1 degrees of freedom when the weights are inverse variances).
    margin : (H, W) float64 ``sqrt(second best) - sqrt(best)`` residual: the distance, in standard
        deviations, by which the choice beat the nearest other wrap combination.
    ambiguous : (H, W) bool, ``margin < min_margin`` (or ``residual > max_residual`` when given): the
        wrap count may be wrong.
    """

    range: np.ndarray
    wraps: np.ndarray
    residual: np.ndarray
    margin: np.ndarray
    ambiguous: np.ndarray


def unwrap_ranges(phase, plan: FrequencyPlan, *, weights=None, max_range: float | None = None,
                  min_margin: float = 2.0, max_residual: float | None = None) -> UnwrapResult:
    """Unwrap several frequencies' phases into one radial distance per pixel.

    Parameters
    ----------
    phase : (F, H, W) wrapped phases in radians, one per frequency of ``plan`` (NaN where unknown).
    weights : (F, H, W) or (F,) inverse variances of each frequency's range (1 / m^2), e.g.
        ``1 / range_sigma(...)**2``. Default: ``f_j^2`` (equal phase noise at every frequency); then
        ``residual`` and ``margin`` are only relative.
    max_range : metres; ranges are sought in ``[0, max_range)``. Default and upper limit: the plan's
        unambiguous range ``c / (2 gcd(f))``.
    min_margin, max_residual : thresholds of the ``ambiguous`` flag (standard deviations; chi-square).
        The residual test is off by default: at high signal-to-noise ratios small systematic differences
        between frequencies (mixed light within a pixel, multipath) dominate it, while the margin only
        asks whether another wrap combination comes close.

    Method: every admissible wrap count ``n`` of the finest frequency gives a candidate range; every
    other frequency takes the wrap count that puts its range nearest to it; the candidate's residual is
    the weighted spread of the resulting ranges about their weighted mean. The best candidate wins; its
    lead over the second best is the margin. Cost: (number of candidates) x F passes over the image.
    """
    phi = np.asarray(phase, dtype=np.float64)
    F = len(plan.frequencies)
    if phi.ndim != 3 or phi.shape[0] != F:
        raise InputError(f"unwrap_ranges: phase must be ({F}, H, W) for {plan.describe()}, found shape {phi.shape}")
    U = plan.wrap_lengths
    r_max = plan.unambiguous_range if max_range is None else float(max_range)
    if not (0 < r_max <= plan.unambiguous_range * (1 + 1e-12)):
        raise InputError(f"unwrap_ranges: max_range must be in (0, {plan.unambiguous_range:.4g}] m (the unambiguous "
                         f"range of {plan.describe()}), found {max_range!r}")
    if weights is None:
        w = (np.asarray(plan.frequencies) / 1e6) ** 2
        w = np.broadcast_to(w.reshape(F, 1, 1), phi.shape)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape == (F,):
            w = np.broadcast_to(w.reshape(F, 1, 1), phi.shape)
        if w.shape != phi.shape:
            raise InputError(f"unwrap_ranges: weights must be (F,) or {phi.shape}, found {w.shape}")
    rho = phi / (2 * np.pi) * U.reshape(F, 1, 1)  # wrapped ranges, metres
    ref = int(np.argmin(U))                          # finest wrap: fewest candidates per metre
    full = r_max >= plan.unambiguous_range * (1 - 1e-12)  # candidates repeat with this period: keep one period
    n_cand = int(np.ceil(r_max / U[ref] - 1e-9))
    H, W = phi.shape[1:]
    best_cost = np.full((H, W), np.inf)
    second_cost = np.full((H, W), np.inf)
    best_range = np.full((H, W), np.nan)
    best_wraps = np.full((F, H, W), -1, dtype=np.int32)
    wsum = w.sum(axis=0)
    for n in range(n_cand):
        cand = rho[ref] + n * U[ref]
        wraps = np.rint((cand[None] - rho) / U.reshape(F, 1, 1))
        r_j = rho + wraps * U.reshape(F, 1, 1)
        with np.errstate(invalid="ignore"):
            mean = (w * r_j).sum(axis=0) / wsum
            cost = (w * (r_j - mean[None]) ** 2).sum(axis=0)
            if not full:
                cost[~(mean < r_max + 0.5 * U[ref])] = np.inf
            better = cost < best_cost
        second_cost = np.where(better, best_cost, np.minimum(second_cost, cost))
        best_cost = np.where(better, cost, best_cost)
        best_range = np.where(better, mean, best_range)
        best_wraps = np.where(better[None], np.nan_to_num(wraps, nan=-1).astype(np.int32), best_wraps)
    finite = np.isfinite(best_cost)
    best_range[~finite] = np.nan
    if full:  # a candidate just past the period is the same as one just above 0
        best_range = np.mod(best_range, plan.unambiguous_range)
    with np.errstate(invalid="ignore"):
        margin = np.sqrt(second_cost) - np.sqrt(best_cost)
    margin[~finite] = 0.0
    best_cost[~finite] = np.nan
    ambiguous = finite & (margin < min_margin)
    if max_residual is not None:
        ambiguous |= finite & (best_cost > max_residual)
    return UnwrapResult(range=best_range, wraps=best_wraps, residual=best_cost, margin=margin, ambiguous=ambiguous)
