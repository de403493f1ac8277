"""Fourier-transform profilometry (Takeda, Ina & Kobayashi 1982): the phase of one fringe image from its
spectrum, as OpenCV contrib's ``SinusoidalPattern`` FTP does it (``modules/structured_light/src/
sinusoidalpattern.cpp``, ``computePhaseMap`` with ``methodId = FTP``).

A fringe image ``I = A + B cos(psi)`` has a spectrum of three lobes: the background at zero frequency and
``B/2 e^{+-i psi}`` around the carrier frequency ``+-k0``. Keeping one lobe and transforming back gives the
analytic signal ``z = B/2 e^{i psi}``: ``psi = arg z``, ``B = 2 |z|``.

OpenCV: the 2-D DFT of the (zero-padded) image; quadrants swapped; a 10 x 10 bin box around zero
frequency cleared; the largest magnitude of each half plane (beyond 5 bins of the centre line) is a carrier
peak; a box of 42 x 42 bins around the right-hand peak kept; the inverse DFT's ``atan2(re, im)`` (arguments
in that order: ``pi / 2 - arg z``). rangekit: the same peak search (a disc of radius ``dc_radius`` bins
cleared, the half plane of positive frequency along the camera's x, or y for rows), but a Gaussian window of
sigma ``0.5 |k0|`` around the peak instead of the fixed box (the box passes the background at short
carrier frequencies and rings at its edges; the window scales with the fringe) and ``arg z`` itself. The
sign of ``psi`` against the projector's phase depends on which way the projector's axis runs in the image:
the caller fixes it (:mod:`rangekit.coded.codecs.sinusoidal`, against the cue).
"""

from __future__ import annotations

import numpy as np

from rangekit._runtime.executor import worker_count

__all__ = ["carrier_peak", "analytic_signal", "DC_RADIUS", "WINDOW_SIGMA"]

DC_RADIUS = 4.0        # bins around zero frequency that cannot be the carrier
WINDOW_SIGMA = 0.5     # the Gaussian window's sigma as a fraction of the carrier's distance from zero


def _freqs(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(ky, kx) bin indices of a full 2-D FFT, each broadcastable to ``shape``."""
    H, W = shape
    return (np.fft.fftfreq(H, 1.0 / H)[:, None].astype(np.float32),
            np.fft.fftfreq(W, 1.0 / W)[None, :].astype(np.float32))


def carrier_peak(spectrum: np.ndarray, vertical: bool, dc_radius: float = DC_RADIUS) -> tuple[float, float]:
    """(ky, kx) bins of the largest magnitude of a full 2-D ``spectrum`` (H, W) complex, in the half plane of
    positive kx (``vertical``: positive ky) beyond ``dc_radius`` bins of zero frequency."""
    ky, kx = _freqs(spectrum.shape)
    half = (ky > 0) | ((ky == 0) & (kx > 0)) if vertical else (kx > 0) | ((kx == 0) & (ky > 0))
    allowed = half & (ky * ky + kx * kx > np.float32(dc_radius * dc_radius))
    mag = np.where(allowed, np.abs(spectrum), np.float32(-1))
    iy, ix = np.unravel_index(int(np.argmax(mag)), mag.shape)
    return float(ky[iy, 0]), float(kx[0, ix])


def _window(shape: tuple[int, int], peak: tuple[float, float], sigma_fraction: float) -> np.ndarray:
    ky, kx = _freqs(shape)
    sigma2 = np.float32((sigma_fraction * np.hypot(*peak)) ** 2)
    return np.exp(-((ky - np.float32(peak[0])) ** 2 + (kx - np.float32(peak[1])) ** 2) / (2 * sigma2))


def analytic_signal(image: np.ndarray, vertical: bool, *, peak: tuple[float, float] | None = None,
                    sigma_fraction: float = WINDOW_SIGMA, workers: int = 0
                    ) -> tuple[np.ndarray, tuple[float, float]]:
    """The analytic signal ``z`` (H, W) complex64 of one fringe ``image`` (H, W), and the carrier peak used
    (found with :func:`carrier_peak` unless given: frames of one sequence share it). ``arg z`` is the
    fringe phase (up to sign), ``2 |z|`` its modulation in the image's units."""
    import scipy.fft   # 0.16 s to import: only the FTP codec needs it, not every decode

    img = np.asarray(image, dtype=np.float32)
    workers = worker_count(workers)
    F = scipy.fft.fft2(img - np.float32(img.mean()), workers=workers)
    if peak is None:
        peak = carrier_peak(F, vertical)
    F *= _window(img.shape, peak, sigma_fraction)
    return scipy.fft.ifft2(F, workers=workers).astype(np.complex64, copy=False), peak
