"""Compiled kernels around the census + semi-global stereo matcher (numba; compiled once, cached on disk):
the census transform, the Hamming cost volume of :func:`rangekit.stereo.census_cost`, the 3 x 3 median.
The aggregation, winner-take-all and left-right check are fused in :mod:`rangekit.stereo._sgm`.

Layouts: images (H, W); census codes (H, W) uint64; the cost volume (H, W, D) with the disparity index
last (contiguous), ``d = min_d + k`` for index ``k``. Kernels take plain arrays, write into preallocated
outputs and never allocate per pixel.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["popcount", "census", "hamming_cost", "median3"]

_M1 = np.uint64(0x5555555555555555)
_M2 = np.uint64(0x3333333333333333)
_M4 = np.uint64(0x0F0F0F0F0F0F0F0F)
_H01 = np.uint64(0x0101010101010101)


@njit(inline="always")
def popcount(x):  # pragma: no cover - compiled
    """Bits set in a uint64 (SWAR; LLVM turns it into one popcnt where the CPU has it)."""
    x = x - ((x >> np.uint64(1)) & _M1)
    x = (x & _M2) + ((x >> np.uint64(2)) & _M2)
    x = (x + (x >> np.uint64(4))) & _M4
    return (x * _H01) >> np.uint64(56)


@njit(parallel=True, cache=True, nogil=True)
def census(img, rx, ry, out):  # pragma: no cover - compiled
    """out[y, x] = bit string of (neighbour < centre) over the (2rx+1) x (2ry+1) window, centre skipped,
    row-major; the image border is replicated. Each row is built one window offset at a time over all x
    (from a row padded by rx replicated pixels each side), so the loop over x is packed."""
    H, W = img.shape
    for y in prange(H):
        pad = np.empty(W + 2 * rx, np.float32)
        code = np.zeros(W, np.uint64)
        c = img[y]
        for j in range(-ry, ry + 1):
            src = img[min(max(y + j, 0), H - 1)]
            for x in range(W + 2 * rx):
                pad[x] = src[min(max(x - rx, 0), W - 1)]
            for i in range(-rx, rx + 1):
                if i == 0 and j == 0:
                    continue
                pv = pad[rx + i:]  # a view read from 0: no negative-index wraparound, so LLVM packs the loop
                for x in range(W):
                    code[x] = (code[x] << np.uint64(1)) | np.uint64(pv[x] < c[x])
        out[y] = code


@njit(parallel=True, cache=True, nogil=True)
def hamming_cost(cl, cr, min_d, invalid, out):  # pragma: no cover - compiled
    """out[y, x, k] = popcount(cl[y, x] ^ cr[y, x - d]), d = min_d + k; ``invalid`` where x - d is outside."""
    H, W = cl.shape
    D = out.shape[2]
    for y in prange(H):
        for x in range(W):
            a = cl[y, x]
            for k in range(D):
                xr = x - (min_d + k)
                if xr < 0 or xr >= W:
                    out[y, x, k] = invalid
                else:
                    out[y, x, k] = np.uint8(popcount(a ^ cr[y, xr]))


@njit(inline="always")
def _cs(a, b):  # pragma: no cover - compiled
    """Compare-exchange: (min, max)."""
    return min(a, b), max(a, b)


@njit(parallel=True, cache=True, nogil=True)
def median3(disp, out):  # pragma: no cover - compiled
    """3 x 3 median over the valid (non-NaN) neighbours of each valid pixel; invalid pixels stay NaN.

    Pixels with 9 valid values take the 19-exchange median-of-9 network (Paeth; Devillard's opt_med9),
    branch-free and packed over a row; the others (borders, NaN neighbours) an insertion sort.
    """
    H, W = disp.shape
    for y in prange(H):
        buf = np.empty(9, np.float32)
        nan_count = np.zeros(W, np.int32)
        if 0 < y < H - 1 and W > 2:
            r0, r1, r2 = disp[y - 1], disp[y], disp[y + 1]
            o = out[y, 1:]
            nc = nan_count[1:]
            for x in range(W - 2):
                p0, p1, p2 = r0[x], r0[x + 1], r0[x + 2]
                p3, p4, p5 = r1[x], r1[x + 1], r1[x + 2]
                p6, p7, p8 = r2[x], r2[x + 1], r2[x + 2]
                nc[x] = (np.int32(p0 != p0) + np.int32(p1 != p1) + np.int32(p2 != p2) + np.int32(p3 != p3)
                         + np.int32(p4 != p4) + np.int32(p5 != p5) + np.int32(p6 != p6) + np.int32(p7 != p7)
                         + np.int32(p8 != p8))
                p1, p2 = _cs(p1, p2)
                p4, p5 = _cs(p4, p5)
                p7, p8 = _cs(p7, p8)
                p0, p1 = _cs(p0, p1)
                p3, p4 = _cs(p3, p4)
                p6, p7 = _cs(p6, p7)
                p1, p2 = _cs(p1, p2)
                p4, p5 = _cs(p4, p5)
                p7, p8 = _cs(p7, p8)
                p0, p3 = _cs(p0, p3)
                p5, p8 = _cs(p5, p8)
                p4, p7 = _cs(p4, p7)
                p3, p6 = _cs(p3, p6)
                p1, p4 = _cs(p1, p4)
                p2, p5 = _cs(p2, p5)
                p4, p7 = _cs(p4, p7)
                p4, p2 = _cs(p4, p2)
                p6, p4 = _cs(p6, p4)
                p4, p2 = _cs(p4, p2)
                o[x] = p4
            nan_count[0] = 1
            nan_count[W - 1] = 1
        else:
            nan_count[:] = 1
        for x in range(W):
            if nan_count[x] == 0:
                continue
            c = disp[y, x]
            if np.isnan(c):
                out[y, x] = c
                continue
            n = 0
            for j in range(max(y - 1, 0), min(y + 2, H)):
                for i in range(max(x - 1, 0), min(x + 2, W)):
                    v = disp[j, i]
                    if not np.isnan(v):
                        k = n  # insertion sort
                        while k > 0 and buf[k - 1] > v:
                            buf[k] = buf[k - 1]
                            k -= 1
                        buf[k] = v
                        n += 1
            if n % 2 == 1:
                out[y, x] = buf[n // 2]
            else:
                out[y, x] = 0.5 * (buf[n // 2 - 1] + buf[n // 2])
