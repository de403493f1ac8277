"""Synthetic laser-line frames with exactly known subpixel centres (tests and benchmarks/laser/bench_laser_peaks.py).

Each frame is a Gaussian profile exp(-2 d^2 / w^2) (w the 1/e^2 full width, d the distance to the true
line) integrated over every pixel's square, scaled to a peak ``height``, on a background, with Gaussian
noise, rounded and clipped to 8 bits. ``off`` is the same background with its own noise.
"""

from __future__ import annotations

import numpy as np
from scipy.special import erf


def _finish(profile, height, noise, seed, background, full=255):
    rng = np.random.default_rng(seed)
    bg = background + np.zeros(profile.shape)
    on = bg + np.asarray(height, float).reshape(-1, 1) * profile + rng.normal(0.0, noise, profile.shape)
    off = bg + rng.normal(0.0, noise, profile.shape)
    q = lambda a: np.clip(np.rint(a), 0, full).astype(np.uint8)  # noqa: E731
    return q(on), q(off)


def row_line(centres, width_px, height=200.0, *, W=320, noise=1.0, seed=0, background=12.0):
    """(on, off) uint8 (H, W), H = len(centres): row v holds the pixel-integrated Gaussian centred on
    column ``centres[v]`` (NaN: no line in that row). ``height`` scalar or (H,)."""
    c = np.asarray(centres, float)[:, None]
    s = width_px / 4.0
    u = np.arange(W)[None, :]
    k = 1.0 / (s * np.sqrt(2.0))
    prof = s * np.sqrt(np.pi / 2.0) * (erf((u + 0.5 - c) * k) - erf((u - 0.5 - c) * k))
    prof = np.nan_to_num(prof / (s * np.sqrt(np.pi / 2.0) * 2.0 * erf(0.5 * k)))   # 1 at a centred pixel
    return _finish(prof, np.broadcast_to(np.asarray(height, float), c.shape[:1]), noise, seed, background)


def curve_line(distance, H, W, width_px, height=200.0, *, noise=1.0, seed=0, background=12.0, ss=6):
    """(on, off) uint8 (H, W) of a line whose distance function ``distance(u, v)`` (arrays of subpixel
    positions -> signed px) is given: the profile averaged over ss x ss samples per pixel. ``height`` a
    number or a function height(u, v) (a brightness that varies along the line)."""
    o = (np.arange(ss) + 0.5) / ss - 0.5
    v, u = np.mgrid[0:H, 0:W].astype(float)
    acc = np.zeros((H, W))
    for dv in o:
        for du in o:
            h = height(u + du, v + dv) if callable(height) else float(height)
            acc += h * np.exp(-2.0 * distance(u + du, v + dv) ** 2 / width_px ** 2)
    return _finish(acc / ss ** 2, np.ones(H), noise, seed, background)


def slanted(angle_deg, u0, v0):
    """Signed distance to the line through (u0, v0) at ``angle_deg`` from the image's vertical."""
    a = np.radians(angle_deg)
    n = np.array([np.cos(a), -np.sin(a)])   # normal of the direction (sin a, cos a)
    return lambda u, v: (u - u0) * n[0] + (v - v0) * n[1]


def circle(cu, cv, radius):
    """Signed distance to the circle of centre (cu, cv) and ``radius`` px."""
    return lambda u, v: np.hypot(u - cu, v - cv) - radius
