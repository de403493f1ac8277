"""Decoding OpenCV contrib's sinusoidal patterns: FTP, PSP and FAPS (``modules/structured_light/src/
sinusoidalpattern.cpp``; frames in :mod:`rangekit.coded.codecs.fringes`), made absolute by the cue.

Frame i of the fringe is ``A + B sin(theta + i d)``, ``theta = 2 pi x / P``, ``d`` the shift (2 pi / 3); as
a cosine, ``A + B cos(phi + i d)`` with ``phi = theta - pi / 2``. The column is ``x = P (phi + pi / 2) / 2 pi``
modulo P.

``ftp``
    ``phi`` from frame 0 alone, by Fourier-transform profilometry (:mod:`rangekit.coded.codecs.ftp`); its
    sign is the one under which the fringe agrees with the cue best (median over the lit pixels). Under a
    projector response ``p ** gamma`` the harmonics lie outside the window: no correction.
``psp``
    ``phi`` from frames 0-2 pixel by pixel, least squares with the steps ``-i d`` (OpenCV's
    ``computePsPhaseMap``: ``atan2((1 - cos d)(I_2 - I_1), sin d (2 I_0 - I_1 - I_2))``, the same for its 2 pi / 3;
    OpenCV first band-passes each frame around the carrier to erase its markers, which rangekit's frames do
    not have). Corrected for the response (3 equal steps).
``faps``
    Fourier-assisted phase shifting (Cong et al. 2015, OpenCV's ``computeFapsPhaseMap``): the steps are
    measured, ``t_1 = psi_1 - psi_0``, ``t_2 = psi_2 - psi_1`` from each frame's FTP phase (OpenCV subtracts
    spatially unwrapped phases, pixel by pixel; rangekit wraps the differences to (-pi, pi], the same where
    unwrapping succeeds, and averages them over a Gaussian of one camera fringe period, as FTP's errors swing
    with the fringe: on the default object this takes FAPS's gross errors from 43% to 0.5%), then with
    ``a = I_0 - I_1``, ``b = I_1 - I_2``::

        phi_1 = atan2((1 - cos t_2) a + (1 - cos t_1) b, sin t_1 b - sin t_2 a)

    is the phase of frame 1 (``phi + t_1`` as a cosine); ``phi = phi_1 - d`` with the projected step d.
    OpenCV's own differences ``a``, ``b`` are of the band-passed frames; rangekit takes the raw ones.
    Corrected for the response as three equal steps (approximately: the steps are measured).

The cue (three frames of one period, steps ``-i d``) gives ``x_cue``; the period of the fringe nearest to it
is taken and pixels where the two disagree by more than a quarter period are ``inconsistent``
(:func:`rangekit.coded.codecs.fringe_result.unwrap_with_cue`). Shadow from the cue's ``2 B``, low contrast from
the fringe's ``2 B`` (FTP: the smaller of its ``2 |2 z|`` and the cue's ``2 B``, as the transform spreads the
amplitude over its window, into shadows; OpenCV: ``computeShadowMask``, the mean of the three frames above 10).
"""

from __future__ import annotations

import cv2
import numpy as np

from rangekit.coded.codecs.fringe_result import AxisMaps, unwrap_with_cue
from rangekit.coded.codecs.fringes import opencv_period
from rangekit.coded.codecs.ftp import analytic_signal
from rangekit.coded.codecs.known_shifts import corrected_phase, phase_known_shifts
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec
from rangekit.errors import DecodeError
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["decode_sinusoidal_axis"]

_TWO_PI = np.float32(2 * np.pi)
_HALF_PI = np.float32(np.pi / 2)


def _cue(fr: CaptureStack, prefix: str, shift: float, n: int, response: ProjectorResponse | None):
    """(x_cue, B, A) of the three one-period cue frames."""
    whole = (slice(None), slice(None))
    steps = [-i * shift for i in range(3)]
    phi, B, A = phase_known_shifts([fr.get(f"{prefix}_cue_s{i}", whole) for i in range(3)], steps)
    theta = np.mod(corrected_phase(phi, response) + _HALF_PI, _TWO_PI)
    return theta * np.float32(n / (2 * np.pi)), B, A


def _column(phi: np.ndarray, period: int) -> np.ndarray:
    """x modulo ``period`` from the cosine phase ``phi`` (module doc)."""
    return np.mod(phi + _HALF_PI, _TWO_PI) * np.float32(period / (2 * np.pi))


def _signed_ftp(z: np.ndarray, period: int, cue: np.ndarray, lit: np.ndarray) -> tuple[np.ndarray, float]:
    """(x modulo period, sign) from the analytic signal: ``phi = sign * arg z``, the sign whose unwrapped
    column agrees with the cue best."""
    psi = np.angle(z).astype(np.float32)
    best = None
    for sign in (1.0, -1.0):
        wrapped = _column(np.float32(sign) * psi, period)
        value, _ = unwrap_with_cue(wrapped, period, cue)
        err = float(np.median(np.abs(value - cue)[lit])) if np.any(lit) else 0.0
        if best is None or err < best[0]:
            best = (err, wrapped, sign)
    return best[1], best[2]


def _smooth(a: np.ndarray, sigma: float) -> np.ndarray:
    """``a`` (H, W) blurred by a Gaussian of ``sigma`` px, float32: on an image shrunk by up to sigma / 4 (the
    result is smooth at that scale), then enlarged back."""
    f = max(1, int(sigma / 4))
    H, W = a.shape
    small = cv2.resize(np.ascontiguousarray(a, np.float32), (max(1, W // f), max(1, H // f)),
                       interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), sigma / f)
    return cv2.resize(small, (W, H), interpolation=cv2.INTER_LINEAR)


def _measured_steps(z0: np.ndarray, z1: np.ndarray, z2: np.ndarray, peak: tuple[float, float]
                    ) -> tuple[np.ndarray, np.ndarray]:
    """FAPS's steps ``t_1 = arg(z_1 conj z_0)``, ``t_2 = arg(z_2 conj z_1)``, each product first averaged over
    a Gaussian of sigma one camera fringe period (FTP's phase errors follow the fringe, so they swing about
    zero over a period while the step changes slowly)."""
    cycles_per_px = float(np.hypot(peak[0] / z0.shape[0], peak[1] / z0.shape[1]))
    sigma = 1.0 / max(cycles_per_px, 1.0 / max(z0.shape))
    out = []
    for u, v in ((z1, z0), (z2, z1)):
        w = u * np.conj(v)
        re, im = _smooth(w.real, sigma), _smooth(w.imag, sigma)
        out.append(np.arctan2(im, re).astype(np.float32))
    return out[0], out[1]


def decode_sinusoidal_axis(fr: CaptureStack, spec: PatternSpec, axis: str, response: ProjectorResponse | None,
                           *, shadow_level: float, workers: int = 0) -> AxisMaps:
    """One coded axis of an ``ftp``, ``psp`` or ``faps`` capture; ``shadow_level`` (raw units) marks the
    pixels that choose FTP's sign."""
    method, o = spec.method, spec.options
    if not o["cue"]:
        raise DecodeError(f"pattern {method!r} without its cue frames gives the column only modulo its period "
                          f"and a spatial unwrapping only relative to an unknown period; rangekit decodes absolute "
                          f"columns: capture with the cue (option cue: true, OpenCV's generate() with "
                          f"nbrOfPeriods 1 for three more frames)")
    prefix = "col" if axis == "columns" else "row"
    n = spec.width if axis == "columns" else spec.height
    period, shift = opencv_period(n, o["n_periods"]), float(o["shift"])
    whole = (slice(None), slice(None))
    cue, B_cue, A_cue = _cue(fr, prefix, shift, n, response)
    lit = np.float32(2) * B_cue >= np.float32(shadow_level)
    vertical = axis == "rows"
    frames = [fr.get(f"{prefix}_fringe_s{i}", whole) for i in range(1 if method == "ftp" else 3)]
    if method == "ftp":
        z, _ = analytic_signal(frames[0], vertical, workers=workers)
        wrapped, _ = _signed_ftp(z, period, cue, lit)
        B = np.float32(2) * np.abs(z)
    else:
        phi, B, _ = phase_known_shifts(frames, [-i * shift for i in range(3)])
        if method == "faps":
            z0, peak = analytic_signal(frames[0], vertical, workers=workers)
            z1, _ = analytic_signal(frames[1], vertical, peak=peak, workers=workers)
            z2, _ = analytic_signal(frames[2], vertical, peak=peak, workers=workers)
            t1, t2 = _measured_steps(z0, z1, z2, peak)
            if np.any(lit) and np.median(t1[lit]) < 0:  # FTP's phase ran against the projector's
                t1, t2 = -t1, -t2
            f0, f1, f2 = (f.astype(np.float32) for f in frames)
            a, b = f0 - f1, f1 - f2
            phi1 = np.arctan2((1 - np.cos(t2)) * a + (1 - np.cos(t1)) * b, np.sin(t1) * b - np.sin(t2) * a)
            phi = np.mod(phi1.astype(np.float32), _TWO_PI)
            phi = corrected_phase(phi, response) - np.float32(shift)
        else:
            phi = corrected_phase(phi, response)
        wrapped = _column(phi, period)
    value, disagree = unwrap_with_cue(wrapped, period, cue)
    signal = np.float32(2) * B
    if method == "ftp":  # the transform spreads the fringe's amplitude over a window: the cue's is per pixel
        signal = np.minimum(signal, np.float32(2) * B_cue)
    return AxisMaps(value=value, signal=signal, reference=np.float32(2) * B_cue, inconsistent=disagree,
                    white=A_cue + B_cue)
