"""Projector response (gamma): its fit from uniform grey levels, and the phase correction.

The model, :class:`rangekit.rig.projector_response.ProjectorResponse`, is a core type (a field of the rig file).

Model
-----
A projector shows pattern value ``p`` in [0, 1] (uint8 ``q`` is ``p = q / 255``) as radiance
``L(p) = L0 + (L1 - L0) * p ** gamma``; ``L0`` is the light it leaks at black. The camera records, at
each pixel, ``I(p) = a + b * L(p)`` with ``a`` (ambient light, dark level) and ``b`` (albedo, shading,
distance fall-off, exposure, gain) unknown and different at every pixel. So

    (I(p) - I(0)) / (I(1) - I(0)) = p ** gamma

at every pixel, whatever ``a``, ``b`` and ``L0``: :func:`fit_response` projects uniform grey levels
including 0 and 1, normalises each pixel this way and fits ``gamma`` to the per-level medians.

Phase shifting under gamma
--------------------------
N-step phase shifting projects ``p_s = 0.5 + 0.5 cos(phi - 2 pi s / N)`` and measures
``atan2(sum I_s sin d_s, sum I_s cos d_s)``, ``d_s = 2 pi s / N``. Through the response the camera sees
``a + b * g(p_s)`` with ``g(p) = p ** gamma``, no longer a sinusoid: its harmonics ``k = m N +- 1`` alias
onto the fundamental and bend the measured phase. ``a`` drops out of both sums (``sum sin d_s =
sum cos d_s = 0`` for N >= 3) and ``b`` out of their ratio, so the measured phase is one function of the
true phase, ``phi_m = F(phi)``, that depends only on ``gamma`` and ``N``: odd, strictly increasing, and
``F(phi + 2 pi / N) = F(phi) + 2 pi / N``. :func:`phase_correction` tabulates ``F`` on a fine grid of
true phases and inverts it into a table of the offset ``phi - F(phi)`` (small and smooth) on a uniform
grid of measured phase, so decoding corrects an image with one vectorised linear table look-up.

Sizes for gamma 2.2 (radians of phase error before correction, RMS over a period): N = 3: 0.20,
N = 4: 0.0075, N = 5: 0.0009, N = 8: 3e-5. Three steps need the correction; eight do not. The table
ignores the 8-bit quantisation of the pattern (a fixed error per projector pixel, not a function of
phase) and blur: projector defocus and the camera's blur damp the aliased harmonics at short periods, so
the table over-corrects a little (on the simulator's default rig, 3 steps with a 16 px period: by about
15%, a residual of 0.07 px RMS).
Where ``F`` is flat the correction amplifies noise: for 3 steps under gamma 2.2 the RMS noise of the
corrected phase is about 1.5 times that of a linear projector, for 4 steps or more about 1.0 times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import cv2
import numpy as np

from rangekit.errors import InputError
from rangekit.image import to_grey
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["ResponseFit", "PhaseCorrection", "fit_response", "phase_correction"]


# --------------------------------------------------------------------------- fit
@dataclass(frozen=True, eq=False)
class ResponseFit:
    """The projector response fitted from uniform grey levels."""

    response: ProjectorResponse
    rms: float                # RMS of (per-level median - level ** gamma), normalised units (0..1); lower is better
    n_pixels: int             # pixels with enough contrast that entered the fit
    levels: np.ndarray        # (K,) float64 pattern values in [0, 1], ascending
    measured: np.ndarray      # (K,) float64 per-level median of (I(p) - I(0)) / (I(1) - I(0))

    def __repr__(self) -> str:
        return (f"ResponseFit(gamma={self.response.gamma:.4f}, rms={self.rms:.2g}, n_pixels={self.n_pixels}, "
                f"levels={len(self.levels)})")


def _grey(image: np.ndarray) -> np.ndarray:
    """(H, W) float32 of a grey or RGB capture (RGB: :func:`rangekit.image.to_grey`)."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        return to_grey(img)
    return img.astype(np.float32)


def fit_response(levels: Sequence[float], images, *, mask: np.ndarray | None = None, min_contrast: float = 0.1,
                 clip_margin: float = 0.004, full_scale: float | None = None) -> ResponseFit:
    """Fit the projector's gamma to captures of uniform grey levels.

    Parameters
    ----------
    levels : (K,) sequence of float
        The pattern value of each image, in [0, 1]; must include 0 and 1 and at least one level in
        between. Any order; each level once.
    images : (K, H, W) or (K, H, W, 3) ndarray, or a sequence of K such images (uint8, uint16 or float)
        The captures, ``images[k]`` of the projector showing ``levels[k]`` everywhere. Colour is averaged
        to grey. Converted to float32 one image at a time.
    mask : (H, W) bool ndarray, optional
        Pixels that may be used (default: all). Pixels near clipping or with too little contrast are
        always left out; they are judged on 5x5 neighbourhoods so that noise does not bias the choice.
    min_contrast : float
        Smallest contrast ``I(1) - I(0)`` (5x5 local mean) as a fraction of full scale.
    clip_margin : float
        Smallest black level ``I(0)`` (5x5 local mean) as a fraction of full scale: darker pixels are
        clipped at 0 by their noise. Pixels with any full-scale white value within 2 px are left out too.
    full_scale : float, optional
        Largest raw value (default 255 for uint8, 65535 for uint16, 1.0 for float images).

    Returns
    -------
    ResponseFit
        ``response.gamma`` minimises the weighted squared difference between the per-level medians of the
        normalised pixels and ``level ** gamma`` (weights: inverse squared standard error of each median).

    Raises
    ------
    InputError
        If 0 or 1 is missing, levels repeat or lie outside [0, 1], there is no level in between, the image
        count or sizes disagree, or fewer than 100 pixels have enough contrast.
    """
    lv = np.asarray(levels, dtype=np.float64).ravel()
    imgs = list(images) if not isinstance(images, np.ndarray) else [images[k] for k in range(images.shape[0])]
    if len(imgs) != lv.size:
        raise InputError(f"fit_response: {lv.size} levels but {len(imgs)} images; give one image per level")
    if not np.all(np.isfinite(lv)) or lv.min(initial=0.0) < 0 or lv.max(initial=1.0) > 1:
        raise InputError(f"fit_response: levels must be pattern values in [0, 1], found {lv.tolist()}")
    if np.unique(lv).size != lv.size:
        raise InputError(f"fit_response: each level must appear once, found {lv.tolist()}")
    missing = [str(v) for v in (0, 1) if not np.any(lv == v)]
    if missing:
        raise InputError(f"fit_response: levels must include {' and '.join(missing)} (black and full white normalise "
                         f"each pixel), found {lv.tolist()}")
    inner = (lv > 0) & (lv < 1)
    if not np.any(inner):
        raise InputError("fit_response: needs at least one level strictly between 0 and 1 to fit gamma, "
                         f"found only {lv.tolist()}")
    shape = np.asarray(imgs[0]).shape
    if len(shape) not in (2, 3) or (len(shape) == 3 and shape[2] != 3):
        raise InputError(f"fit_response: images must be (H, W) grey or (H, W, 3) RGB, found shape {shape}")
    for k, im in enumerate(imgs):
        if np.asarray(im).shape != shape:
            raise InputError(f"fit_response: image {k} has shape {np.asarray(im).shape}, image 0 has {shape}; all "
                             "captures must have the same size")
    dtype = np.asarray(imgs[0]).dtype
    fs = float(full_scale if full_scale is not None else
               255 if dtype == np.uint8 else 65535 if dtype == np.uint16 else 1.0)
    black, white = _grey(imgs[int(np.flatnonzero(lv == 0)[0])]), _grey(imgs[int(np.flatnonzero(lv == 1)[0])])
    # Choose pixels on 5x5 local means (and the local maximum of white), not on each pixel's own noisy
    # black and white: a per-pixel cut such as "black > 0" keeps the pixels whose noise lifted their
    # black reference, and biases every normalised level (by 0.7% in gamma on a dark turntable).
    black_s, white_s = cv2.blur(black, (5, 5)), cv2.blur(white, (5, 5))
    white_max = cv2.dilate(white, np.ones((5, 5), np.uint8))
    use = (white_s - black_s >= min_contrast * fs) & (white - black >= 0.5 * min_contrast * fs) \
        & (black_s >= clip_margin * fs) & (white_max < fs)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        if m.shape != black.shape:
            raise InputError(f"fit_response: mask has shape {m.shape}, the images are {black.shape} (H, W)")
        use &= m
    n = int(np.count_nonzero(use))
    if n < 100:
        raise InputError(f"fit_response: only {n} pixel(s) have white - black >= {min_contrast:.0%} of full scale "
                         f"({min_contrast * fs:g}), black >= {clip_margin * fs:g} and white below {fs:g} "
                         "(unclipped); point the projector at a matte surface the camera sees, raise the exposure "
                         "(or lower it if white is clipped), give full_scale for 10- to 14-bit data in uint16, or "
                         "lower min_contrast")
    b0, span = black[use], (white - black)[use]
    order = np.argsort(lv)
    lv = lv[order]
    med = np.empty(lv.size)
    sem = np.empty(lv.size)
    for j, k in enumerate(order):
        v = (_grey(imgs[k])[use] - b0) / span
        q1, med[j], q3 = np.percentile(v, [25, 50, 75])
        sem[j] = 1.2533 * (q3 - q1) / 1.349 / math.sqrt(n)  # standard error of a median, normal noise
    inner = (lv > 0) & (lv < 1)
    gamma = _fit_gamma(lv[inner], med[inner], sem[inner])
    rms = float(np.sqrt(np.mean((med[inner] - lv[inner] ** gamma) ** 2)))
    return ResponseFit(ProjectorResponse(gamma), rms, n, lv, med)


def _fit_gamma(p: np.ndarray, m: np.ndarray, sem: np.ndarray) -> float:
    """Weighted least squares of ``m = p ** gamma`` (Gauss-Newton from a log-log start)."""
    w = 1.0 / (sem ** 2 + 1e-8)
    ok = m > 0.01
    if np.any(ok):  # start: gamma = log m / log p, weighted by the level's relative precision
        lw = (m[ok] / np.maximum(sem[ok], 1e-6)) ** 2 * np.log(p[ok]) ** 2
        gamma = float(np.sum(lw * np.log(m[ok]) / np.log(p[ok])) / np.sum(lw))
    else:
        gamma = 1.0
    gamma = min(max(gamma, 0.05), 20.0)
    for _ in range(100):
        f = p ** gamma
        J = f * np.log(p)                  # d f / d gamma
        step = float(np.sum(w * J * (m - f)) / max(np.sum(w * J * J), 1e-300))
        gamma = min(max(gamma + step, 0.5 * gamma), 2.0 * gamma)
        if abs(step) < 1e-10 * gamma:
            break
    return gamma


# --------------------------------------------------------------------------- phase correction
@dataclass(frozen=True, eq=False)
class PhaseCorrection:
    """Maps the wrapped phase measured by N-step phase shifting under ``gamma`` to the true phase.

    Call it on an array of measured phases (radians, any range; typically [0, 2 pi)) to get the true
    phases in [0, 2 pi), float32, same shape. See the module docstring for the model.
    """

    gamma: float
    steps: int
    offset: np.ndarray    # (M + 1,) float32 true - measured phase (radians) at measured phases 2 pi i / M

    def __call__(self, phase: np.ndarray) -> np.ndarray:
        two_pi = np.float32(2 * np.pi)
        ph = np.mod(np.asarray(phase, dtype=np.float32), two_pi)
        m = self.offset.size - 1
        x = ph * np.float32(m / (2 * np.pi))          # linear interpolation on the uniform table
        i = np.minimum(x.astype(np.int32), m - 1)
        f = x - i.astype(np.float32)
        out = ph + self.offset[i] * (1 - f) + self.offset[i + 1] * f
        out %= two_pi
        return out

    def slope(self, phase: np.ndarray) -> np.ndarray:
        """d(true phase) / d(measured phase) at the measured ``phase`` (the table's piecewise slope), float32:
        how much the correction stretches a phase error."""
        m = self.offset.size - 1
        x = np.mod(np.asarray(phase, dtype=np.float32), np.float32(2 * np.pi)) * np.float32(m / (2 * np.pi))
        i = np.minimum(x.astype(np.int32), m - 1)
        return 1 + (self.offset[i + 1] - self.offset[i]) * np.float32(m / (2 * np.pi))

    @property
    def max_offset(self) -> float:
        """Largest |true - measured| phase, radians."""
        return float(np.abs(self.offset).max())

    def __repr__(self) -> str:
        return f"PhaseCorrection(gamma={self.gamma:g}, steps={self.steps}, max_offset={self.max_offset:.3g} rad)"


def phase_correction(response: ProjectorResponse | float, steps: int, *, samples: int = 4096) -> PhaseCorrection:
    """The correction of ``steps``-step phase shifting for a projector with ``response``.

    Parameters
    ----------
    response : ProjectorResponse or float (gamma)
    steps : int >= 3
        Phase steps N of the pattern (``d_s = 2 pi s / N``, as :func:`rangekit.coded.phase.phase_from_steps`).
    samples : int
        Grid size of the tables over one period (of true phase, and of measured phase).

    Returns
    -------
    PhaseCorrection
        Cached per (gamma, steps, samples); the identity (zero offsets) for gamma 1.
    """
    gamma = response.gamma if isinstance(response, ProjectorResponse) else ProjectorResponse(response).gamma
    if not isinstance(steps, (int, np.integer)) or isinstance(steps, bool) or steps < 3:
        raise InputError(f"phase_correction: steps must be an integer >= 3, found {steps!r}")
    if not isinstance(samples, (int, np.integer)) or samples < 64:
        raise InputError(f"phase_correction: samples must be >= 64, found {samples!r}")
    return PhaseCorrection(gamma, int(steps), _table(gamma, int(steps), int(samples)))


@lru_cache(maxsize=32)
def _table(gamma: float, steps: int, samples: int) -> np.ndarray:
    """Offsets true - measured on a uniform grid of measured phase, first value repeated at the end."""
    if gamma == 1.0:  # exactly the identity
        table = np.zeros(samples + 1, np.float32)
        table.setflags(write=False)
        return table
    phi = np.arange(samples) * (2 * np.pi / samples)
    d = 2 * np.pi * np.arange(steps) / steps
    I = (0.5 + 0.5 * np.cos(phi[:, None] - d[None, :])) ** gamma     # (M, N) relative radiance
    measured = np.arctan2(I @ np.sin(d), I @ np.cos(d))
    offset = np.angle(np.exp(1j * (phi - measured)))                    # wrapped to (-pi, pi]
    slope = np.diff(np.unwrap(measured)) * (samples / (2 * np.pi))     # d phi_m / d phi
    if slope.min() < 0.01:
        raise InputError(f"phase_correction: gamma {gamma:g} is too strong for {steps}-step phase shifting (the "
                         f"measured phase barely moves with the true phase, slope {slope.min():.2g}, so noise would "
                         "grow a hundredfold); use more steps")
    measured = np.mod(measured, 2 * np.pi)
    order = np.argsort(measured, kind="stable")
    grid = np.arange(samples + 1) * (2 * np.pi / samples)
    table = np.interp(grid, measured[order], offset[order], period=2 * np.pi).astype(np.float32)
    table.setflags(write=False)
    return table
