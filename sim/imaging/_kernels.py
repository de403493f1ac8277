"""Compiled inner loops of the simulated camera (numba; compiled once, cached on disk, GIL released).

A simulated frame was a dozen full-image numpy passes (the bilinear gather of the projected radiance,
the noise, the ADC), each with its temporaries. These loops do the same float32 operations, in the same
order, in one pass, so every frame's bytes are unchanged (no fast-math: no fused multiply-add, no
reordering). Acquisition renders frames on two threads (:mod:`rangekit.app.acquire.frame_writer`): the kernels
release the GIL and run on one thread each.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["add_direct", "noise_and_adc"]


@njit(cache=True, nogil=True)
def add_direct(img, L, i00, dx, dy, w00, w10, w01, w11, direct, lit_idx):  # pragma: no cover - compiled
    """``img[lit_idx] += direct * bilinear(L)``: img (H*W, C) float32, L (Hp*Wp, C) float32 radiance,
    i00 (n,) top-left sample index, dx/dy the index steps, w** (n,) float32 weights, direct (n, C)."""
    n, C = direct.shape
    for j in range(n):
        i = i00[j]
        p = lit_idx[j]
        for c in range(C):
            v = L[i, c] * w00[j] + L[i + dx, c] * w10[j]
            v = v + L[i + dy, c] * w01[j]
            v = v + L[i + dy + dx, c] * w11[j]
            img[p, c] += direct[j, c] * v


@njit(cache=True, nogil=True)
def noise_and_adc(img, z, full_well, read2, full_well_clip, scale, max_value, out):  # pragma: no cover
    """The sensor of :func:`rangekit.sim.imaging.sensor.digitise` on flat float32 ``img`` (modified) with the
    standard normals ``z`` (None: no noise): ``img += sqrt(max(img, 0) * full_well + read2) * z / full_well``,
    then (``full_well_clip``) ``clip(img, 0, 1)``, ``img * scale`` clipped to ``[0, max_value]``, rounded
    half to even into ``out``. Every constant is float32, as numpy computes it."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(img.size):
        x = img[i]
        if z is not None:
            s = np.sqrt((x if x > zero else zero) * full_well + read2)
            x = x + s * z[i] / full_well
        if full_well_clip:
            x = min(max(x, zero), one)
        x = x * scale
        x = min(max(x, zero), max_value)
        out[i] = np.rint(x)
