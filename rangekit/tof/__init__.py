"""Time of flight: range from pulsed round-trip times and from continuous-wave correlation samples.

Fusiello ch. 13.3. Units: metres, seconds, hertz, radians; images (H, W) in camera pixels.

Pulsed: light returns after ``dt``, so the radial distance is ``r = c dt / 2`` (1 mm is 6.7 ps of
round trip).

Continuous wave (CW): the emitter is modulated at ``f`` (wavelength ``lambda = c / f``); the light
returning from range ``r`` is delayed in phase by ``phi = 2 pi f 2 r / c`` (eq. 13.8). The pixel
correlates it with the reference shifted by ``theta_k`` and integrates, giving sample ``k``::

    S_k = B + A cos(phi - theta_k)          (offset B, amplitude A, any >= 3 distinct steps theta_k)

Writing ``S_k = B + a cos(theta_k) + b sin(theta_k)`` with ``a = A cos(phi)``, ``b = A sin(phi)`` makes
the N-bucket estimate a linear least-squares fit (:func:`phase_amplitude_offset`). One frequency gives
``r = n lambda/2 + phi lambda / (4 pi)`` (eq. 13.9): known modulo ``lambda / 2`` (the *unambiguous
range*, 1.875 m at 80 MHz). Several frequencies fix the wrap counts ``n_j``: the combined unambiguous
range is ``c / (2 gcd(f_j))`` (16/80/120 MHz: 18.75 m; 80/100 MHz: 7.5 m). :func:`unwrap_ranges`
searches every admissible wrap count of the finest frequency, rounds the others to it and keeps the
candidate whose per-frequency ranges agree best, weighted by their inverse variances.

Noise: with per-sample noise ``sigma_s`` (shot noise of the offset plus read noise, in the samples'
units) the phase noise is ``sigma_phi = sqrt(2 / N) sigma_s / A`` and the range noise
``sigma_r = c sigma_phi / (4 pi f)``; unwrapped ranges of several frequencies are averaged with weights
``1 / sigma_r^2``, so ``sigma_r`` of the combination is ``(sum 1 / sigma_r,j^2)^(-1/2)``.

A ToF camera measures radial distance along the pixel's ray, not ``z``: :func:`range_to_depth` and
:func:`range_to_points` convert with the camera model (lens distortion included).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import reduce

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import apply_T

__all__ = [
    "C_LIGHT",
    "FrequencyPlan",
    "PhaseMaps",
    "UnwrapResult",
    "ToFResult",
    "pulsed_range",
    "phase_amplitude_offset",
    "phase_to_range",
    "range_sigma",
    "unwrap_ranges",
    "flying_pixels",
    "camera_rays",
    "range_to_depth",
    "range_to_points",
    "decode_cw",
]

#: Speed of light in vacuum, m/s (exact by definition of the metre).
C_LIGHT = 299_792_458.0


# ---------------------------------------------------------------------------------------------- plan
@dataclass(frozen=True)
class FrequencyPlan:
    """Modulation frequencies and the phase steps sampled at each: the order raw samples come in.

    Samples are frequency-major: all steps of ``frequencies[0]``, then all of ``frequencies[1]``...

    frequencies : Hz, each > 0 (e.g. (16e6, 80e6, 120e6) as Kinect v2).
    steps : per frequency, the reference phase shifts ``theta_k`` in radians (at least 3 distinct ones
        modulo 2 pi), e.g. (0, 2 pi/3, 4 pi/3) for 3-bucket or (0, pi/2, pi, 3 pi/2) for 4-bucket.
    """

    frequencies: tuple[float, ...]
    steps: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        f = tuple(float(v) for v in np.atleast_1d(np.asarray(self.frequencies, dtype=np.float64)))
        if not f or not all(math.isfinite(v) and v > 0 for v in f):
            raise InputError(f"FrequencyPlan: frequencies must be positive Hz values, found {self.frequencies!r}")
        if len(set(f)) != len(f):
            raise InputError(f"FrequencyPlan: frequencies must be distinct, found {self.frequencies!r}")
        steps = tuple(tuple(float(t) for t in s) for s in self.steps)
        if len(steps) != len(f):
            raise InputError(f"FrequencyPlan: {len(f)} frequencies but {len(steps)} lists of phase steps")
        for fj, s in zip(f, steps):
            wrapped = np.round(np.mod(s, 2 * np.pi), 9) % round(2 * np.pi, 9)
            if len(s) < 3 or len(set(wrapped.tolist())) < 3 or not all(math.isfinite(t) for t in s):
                raise InputError(f"FrequencyPlan: {fj / 1e6:g} MHz needs at least 3 distinct phase steps "
                                 f"(radians), found {s!r}")
        object.__setattr__(self, "frequencies", f)
        object.__setattr__(self, "steps", steps)

    @classmethod
    def uniform(cls, frequencies, n_steps: int = 4) -> "FrequencyPlan":
        """``n_steps`` equally spaced steps ``2 pi k / n_steps`` at every frequency (Hz)."""
        if int(n_steps) != n_steps or n_steps < 3:
            raise InputError(f"FrequencyPlan.uniform: n_steps must be an integer >= 3, found {n_steps!r}")
        freqs = tuple(float(v) for v in np.atleast_1d(frequencies))
        step = tuple(2 * np.pi * k / int(n_steps) for k in range(int(n_steps)))
        return cls(freqs, tuple(step for _ in freqs))

    @property
    def n_samples(self) -> int:
        """Raw samples per frame: the sum of the step counts."""
        return sum(len(s) for s in self.steps)

    @property
    def wrap_lengths(self) -> np.ndarray:
        """(F,) metres: ``c / (2 f)``, the range each frequency's phase wraps at."""
        return C_LIGHT / (2 * np.asarray(self.frequencies))

    @property
    def unambiguous_range(self) -> float:
        """Metres: ``c / (2 gcd(f))`` with the frequencies rounded to 1 Hz (the combined wrap length)."""
        g = reduce(math.gcd, (int(round(v)) for v in self.frequencies))
        return C_LIGHT / (2 * g)

    def slices(self) -> list[slice]:
        """Where each frequency's samples sit in a raw stack."""
        out, k = [], 0
        for s in self.steps:
            out.append(slice(k, k + len(s)))
            k += len(s)
        return out

    def describe(self) -> str:
        """E.g. ``16/80/120 MHz x 3/3/3 steps``."""
        mhz = "/".join(f"{v / 1e6:g}" for v in self.frequencies)
        steps = "/".join(str(len(s)) for s in self.steps)
        return f"{mhz} MHz x {steps} steps"

    def to_dict(self) -> dict:
        return {"frequencies_hz": list(self.frequencies), "steps_rad": [list(s) for s in self.steps]}

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "frequency plan") -> "FrequencyPlan":
        if not isinstance(data, dict) or "frequencies_hz" not in data or "steps_rad" not in data:
            raise InputError(f"{where}: expected an object with 'frequencies_hz' and 'steps_rad', found {data!r}")
        try:
            return cls(tuple(data["frequencies_hz"]), tuple(tuple(s) for s in data["steps_rad"]))
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: {exc}") from None


# ---------------------------------------------------------------------------------------------- pulsed
def pulsed_range(round_trip_s: np.ndarray) -> np.ndarray:
    """Radial distance ``r = c dt / 2`` in metres from round-trip times in seconds (NaN stays NaN)."""
    return 0.5 * C_LIGHT * np.asarray(round_trip_s, dtype=np.float64)


# ---------------------------------------------------------------------------------------------- N-bucket
@dataclass(frozen=True, eq=False)
class PhaseMaps:
    """Per-frequency N-bucket estimates, each (F, H, W) float64 in the samples' units (phase in radians).

    phase : in [0, 2 pi), the delay ``phi = 4 pi f r / c`` modulo 2 pi.
    amplitude : ``A`` (>= 0). offset : ``B``.
    """

    phase: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray


def _check_samples(samples, plan: FrequencyPlan, where: str) -> np.ndarray:
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
    S = _check_samples(samples, plan, "phase_amplitude_offset")
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


# ---------------------------------------------------------------------------------------------- geometry
def _check_range_map(range_map, camera: PinholeCamera, where: str) -> np.ndarray:
    r = np.asarray(range_map, dtype=np.float64)
    if r.shape != (camera.height, camera.width):
        raise InputError(f"{where}: range map is {r.shape[1] if r.ndim == 2 else '?'}x"
                         f"{r.shape[0] if r.ndim >= 1 else '?'} (shape {r.shape}) but camera {camera.name!r} is "
                         f"{camera.width}x{camera.height}")
    return r


_RAY_CACHE: dict[bytes, np.ndarray] = {}


def camera_rays(camera: PinholeCamera) -> np.ndarray:
    """(H, W, 3) float64 unit ray directions of every pixel centre in the camera frame (distortion undone).

    Read-only; cached for the last few lenses (undoing the distortion of every pixel is the costly part of
    a ToF decode, and a sensor's lens does not change between frames).
    """
    key = np.concatenate([camera.K.ravel(), camera.dist.ravel(), [camera.width, camera.height]]).tobytes()
    d = _RAY_CACHE.get(key)
    if d is None:
        xy = camera.pixels_to_normalized(camera.pixel_grid())
        d = np.column_stack([xy, np.ones(len(xy))])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = d.reshape(camera.height, camera.width, 3)
        d.flags.writeable = False
        if len(_RAY_CACHE) >= 4:
            _RAY_CACHE.pop(next(iter(_RAY_CACHE)))
        _RAY_CACHE[key] = d
    return d


def range_to_depth(range_map, camera: PinholeCamera) -> np.ndarray:
    """(H, W) camera-frame z in metres from radial distances along each pixel's ray (NaN stays NaN).

    ``z = r * d_z`` with ``d`` the unit ray of the pixel centre, lens distortion undone exactly.
    """
    r = _check_range_map(range_map, camera, "range_to_depth")
    return r * camera_rays(camera)[..., 2]


def range_to_points(range_map, camera: PinholeCamera, *, frame: str = "world") -> np.ndarray:
    """(H, W, 3) points in metres, NaN where the range is NaN, in the ``"camera"`` or ``"world"`` frame
    (``camera.T_world_cam``)."""
    if frame not in ("camera", "world"):
        raise InputError(f"range_to_points: frame must be 'camera' or 'world', found {frame!r}")
    r = _check_range_map(range_map, camera, "range_to_points")
    p = r[..., None] * camera_rays(camera)
    if frame == "world" and not np.array_equal(camera.T_world_cam, np.eye(4)):
        p = apply_T(camera.T_world_cam, p.reshape(-1, 3)).reshape(p.shape)
    return p


def flying_pixels(range_map, camera: PinholeCamera, *, max_angle_deg: float = 15.0) -> np.ndarray:
    """(H, W) bool: mixed ("flying") pixels at depth edges.

    A pixel that averages a foreground and a background surface lands between them on its ray, so the
    3D vectors to its neighbours on *both* sides (left and right, or above and below, or either
    diagonal pair) run nearly along the ray. A pixel is flagged when, for some neighbour pair, both
    vectors make less than ``max_angle_deg`` with the ray. A true edge pixel has one such neighbour
    only, and is kept; so is a surface seen at up to ``90 - max_angle_deg`` degrees of incidence.
    Pixels with NaN neighbours on both sides are not judged.
    """
    r = _check_range_map(range_map, camera, "flying_pixels")
    d = camera_rays(camera)
    p = r[..., None] * d
    H, W = r.shape
    pad = np.pad(p, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
    cos_max = math.cos(math.radians(max_angle_deg))

    def along_ray(dy: int, dx: int) -> np.ndarray:
        q = pad[1 + dy: 1 + dy + H, 1 + dx: 1 + dx + W] - p
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.abs(np.einsum("ijk,ijk->ij", q, d)) / np.linalg.norm(q, axis=2)
        return c > cos_max  # NaN compares False

    flagged = np.zeros((H, W), dtype=bool)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        flagged |= along_ray(dy, dx) & along_ray(-dy, -dx)
    return flagged & np.isfinite(r)


# ---------------------------------------------------------------------------------------------- pipeline
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
    low_signal, ambiguous, flying, valid : bool masks; ``valid`` = not any of the three and finite.
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
    valid: np.ndarray

    def __repr__(self) -> str:
        H, W = self.valid.shape
        n = H * W
        return (f"ToFResult({W}x{H}, valid={self.valid.sum() / n:.1%}, low_signal={self.low_signal.sum() / n:.1%}, "
                f"ambiguous={self.ambiguous.sum() / n:.1%}, flying={self.flying.sum() / n:.1%})")


def decode_cw(samples, plan: FrequencyPlan, camera: PinholeCamera, *, electrons_per_unit: float = 1.0,
              read_noise_e: float = 0.0, max_range: float | None = None, min_snr: float = 3.0,
              min_margin: float = 2.0, flying_angle_deg: float | None = 15.0,
              saturation: float | None = None) -> ToFResult:
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
    flying_angle_deg : threshold of :func:`flying_pixels`; None disables the filter.
    saturation : sample value at which the sensor clips; pixels with any sample at or above it are
        ``low_signal`` (their phase is biased). None: no check.
    """
    S = _check_samples(samples, plan, "decode_cw")
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
    flying = (flying_pixels(r, camera, max_angle_deg=flying_angle_deg) if flying_angle_deg is not None
              else np.zeros(r.shape, bool))
    valid = np.isfinite(r) & ~low & ~un.ambiguous & ~flying
    r_valid = np.where(valid, r, np.nan)
    depth = range_to_depth(r_valid, camera)
    pts = range_to_points(r_valid, camera, frame="world")[valid]
    conf = np.where(valid, snr / (snr + 5.0), 0.0).astype(np.float32)
    return ToFResult(range=r_valid, depth=depth, points=pts, confidence=conf,
                     sigma_range=np.where(valid, sigma_comb, np.nan), amplitude=maps.amplitude,
                     offset=maps.offset, phase=maps.phase, unwrap=un, low_signal=low,
                     ambiguous=un.ambiguous & ~low, flying=flying & ~low & ~un.ambiguous, valid=valid)
