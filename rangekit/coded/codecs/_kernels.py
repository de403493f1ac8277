"""Compiled inner loop of the micro phase shifting decoder (numba; compiled once, cached on disk).

Why numba: each pixel tries every period of the first frequency (about n / p_0 candidates, 17 on a 1280 px
projector) against every other frequency's frame (9 with SLStudio's set): 150 model values per pixel,
about 60 full-image numpy passes. One loop per image row does it with two products per value (the
candidate's angle by the angle-addition rule from per-pixel and per-candidate tables).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["micro_search"]


@njit(parallel=True, cache=True, nogil=True)
def micro_search(stack, e_idx, phi0, a, b, p0, ratio, psi, lut, n, x_out, best_out, second_out):  # pragma: no cover
    """For every pixel, the column ``x_k = p0 (phi0 / 2 pi + k)`` inside [-0.5, n - 0.5] whose predicted frames
    ``a + b lut[(0.5 + 0.5 cos(2 pi x_k / p_j - psi_j)) (L - 1)]`` (``2 pi x_k / p_j = ratio_j (phi0 + 2 pi k)``)
    best match the frames ``stack[e_idx[j]]``: x_out, and the best and second-best sums of squared residuals
    (NaN / inf where b <= 0 or no candidate)."""
    J = e_idx.shape[0]
    H = phi0.shape[0]
    W = phi0.shape[1]
    L1 = lut.shape[0] - 1
    two_pi = 2.0 * math.pi
    kmax = int(n / p0) + 2
    ck = np.empty((kmax + 2, J))
    sk = np.empty((kmax + 2, J))
    for t in range(kmax + 2):
        for j in range(J):
            ck[t, j] = math.cos(two_pi * (t - 1) * ratio[j])
            sk[t, j] = math.sin(two_pi * (t - 1) * ratio[j])
    for y in prange(H):
        ca = np.empty(J)
        sa = np.empty(J)
        e = np.empty(J)
        for x in range(W):
            bb = b[y, x]
            ph = phi0[y, x]
            x_out[y, x] = np.nan
            best_out[y, x] = np.inf
            second_out[y, x] = np.inf
            if not (bb > 0.0) or not (ph == ph):
                continue
            aa = a[y, x]
            for j in range(J):
                alpha = ratio[j] * ph - psi[j]
                ca[j] = math.cos(alpha)
                sa[j] = math.sin(alpha)
                e[j] = stack[e_idx[j], y, x]
            base = ph / two_pi
            k0 = int(math.ceil(-0.5 / p0 - base))
            k1 = int(math.floor((n - 0.5) / p0 - base))
            best = np.inf
            second = np.inf
            xb = np.nan
            for k in range(max(k0, -1), min(k1, kmax) + 1):
                t = k + 1
                r = 0.0
                for j in range(J):
                    c = ca[j] * ck[t, j] - sa[j] * sk[t, j]
                    q = (0.5 + 0.5 * c) * L1
                    i = int(q + 0.5)
                    if i < 0:
                        i = 0
                    elif i > L1:
                        i = L1
                    d = e[j] - aa - bb * lut[i]
                    r += d * d
                if r < best:
                    second = best
                    best = r
                    xb = p0 * (base + k)
                elif r < second:
                    second = r
            x_out[y, x] = xb
            best_out[y, x] = best
            second_out[y, x] = second
