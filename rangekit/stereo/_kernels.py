"""Compiled inner loops of the census + semi-global stereo matcher (numba; compiled once, cached on disk).

Layouts: images (H, W); census codes (H, W) uint64; the matching cost and the aggregated cost are
(H, W, D) with the disparity index last (contiguous), ``d = min_d + k`` for index ``k``. Costs are small
integers (Hamming distances); the path costs L_r are kept in float32 row buffers (exact for these small
integers, and numba keeps float32 arithmetic in float32) and their sums per pass are stored as uint16.
Kernels take plain arrays, write into preallocated outputs and never allocate per pixel.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["popcount", "census", "hamming_cost", "aggregate", "winner_take_all", "right_winner",
           "lr_check", "median3"]

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
                for x in range(W):
                    code[x] = (code[x] << np.uint64(1)) | np.uint64(pad[x + rx + i] < c[x])
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
def _start(c, cur):  # pragma: no cover - compiled
    """A path enters the image here: L = C. Returns min_k L."""
    best = np.float32(1e30)
    for d in range(c.shape[0]):
        v = np.float32(c[d])
        cur[d] = v
        best = min(best, v)
    return best


@njit(inline="always")
def _step(prev, prev_min, c, cur, P1, P2):  # pragma: no cover - compiled
    """One SGM recurrence (Hirschmuller 2008, eq. 13) at one pixel; returns min_k of the new L.

    cur[d] = c[d] + min(prev[d], prev[d-1] + P1, prev[d+1] + P1, prev_min + P2) - prev_min.
    float32 (exact for these small integers) so that numba keeps 16 lanes per AVX-512 register; the inner
    loop is branch-free so that LLVM vectorises it, the two ends are done apart.
    """
    D = c.shape[0]
    jump = prev_min + P2
    v = min(min(prev[0], prev[1] + P1), jump) + np.float32(c[0]) - prev_min
    cur[0] = v
    best = v
    v = min(min(prev[D - 1], prev[D - 2] + P1), jump) + np.float32(c[D - 1]) - prev_min
    cur[D - 1] = v
    best = min(best, v)
    for d in range(1, D - 1):
        v = min(min(prev[d], min(prev[d - 1], prev[d + 1]) + P1), jump) + np.float32(c[d]) - prev_min
        cur[d] = v
        best = min(best, v)
    return best


@njit(cache=True, nogil=True, fastmath=True)
def _raster_pass(cost, P1, P2, reverse, diagonals, acc):  # pragma: no cover - compiled
    """acc[y, x, :] = sum of L_r over the paths whose predecessors come earlier in raster order (``reverse``:
    later), in one scan: horizontal, vertical and (``diagonals``) both diagonals (Hirschmuller 2008,
    OpenCV's MODE_HH). Forward: r = (1, 0), (0, 1), (1, 1), (-1, 1) as (dx, dy); reverse: their negatives.
    Each path keeps its previous row of L in a (W, D) buffer; nothing is allocated per pixel.
    """
    H, W, D = cost.shape
    s = -1 if reverse else 1
    p1 = np.float32(P1)
    p2 = np.float32(P2)
    prev_v = np.empty((W, D), np.float32)
    cur_v = np.empty((W, D), np.float32)
    prev_a = np.zeros((W, D), np.float32)
    cur_a = np.zeros((W, D), np.float32)
    prev_b = np.zeros((W, D), np.float32)
    cur_b = np.zeros((W, D), np.float32)
    pmin_v = np.empty(W, np.float32)
    cmin_v = np.empty(W, np.float32)
    pmin_a = np.empty(W, np.float32)
    cmin_a = np.empty(W, np.float32)
    pmin_b = np.empty(W, np.float32)
    cmin_b = np.empty(W, np.float32)
    prev_h = np.empty(D, np.float32)
    cur_h = np.empty(D, np.float32)
    hmin = np.float32(0.0)
    for i in range(H):
        y = H - 1 - i if reverse else i
        for j in range(W):
            x = W - 1 - j if reverse else j
            c = cost[y, x]
            # horizontal, predecessor (x - s, y)
            if j == 0:
                hmin = _start(c, cur_h)
            else:
                hmin = _step(prev_h, hmin, c, cur_h, p1, p2)
            # vertical, predecessor (x, y - s)
            if i == 0:
                cmin_v[x] = _start(c, cur_v[x])
            else:
                cmin_v[x] = _step(prev_v[x], pmin_v[x], c, cur_v[x], p1, p2)
            if diagonals:
                # diagonal a, predecessor (x - s, y - s)
                xp = x - s
                if i == 0 or xp < 0 or xp >= W:
                    cmin_a[x] = _start(c, cur_a[x])
                else:
                    cmin_a[x] = _step(prev_a[xp], pmin_a[xp], c, cur_a[x], p1, p2)
                # diagonal b, predecessor (x + s, y - s)
                xp = x + s
                if i == 0 or xp < 0 or xp >= W:
                    cmin_b[x] = _start(c, cur_b[x])
                else:
                    cmin_b[x] = _step(prev_b[xp], pmin_b[xp], c, cur_b[x], p1, p2)
            # S_pass(p, d) = sum of the paths' L (the diagonal buffers stay 0 with 4 paths)
            a = acc[y, x]
            cv = cur_v[x]
            ca = cur_a[x]
            cb = cur_b[x]
            for d in range(D):
                a[d] = np.uint16(cur_h[d] + cv[d] + ca[d] + cb[d])
            prev_h, cur_h = cur_h, prev_h
        prev_v, cur_v = cur_v, prev_v
        pmin_v, cmin_v = cmin_v, pmin_v
        prev_a, cur_a = cur_a, prev_a
        pmin_a, cmin_a = cmin_a, pmin_a
        prev_b, cur_b = cur_b, prev_b
        pmin_b, cmin_b = cmin_b, pmin_b


@njit(parallel=True, cache=True, nogil=True)
def aggregate(cost, P1, P2, diagonals, acc_forward, acc_reverse):  # pragma: no cover - compiled
    """Semi-global aggregation: the forward and the reverse raster pass (4 or 8 paths in all), run as two
    parallel tasks. S = acc_forward + acc_reverse."""
    for t in prange(2):
        if t == 0:
            _raster_pass(cost, P1, P2, False, diagonals, acc_forward)
        else:
            _raster_pass(cost, P1, P2, True, diagonals, acc_reverse)


@njit(parallel=True, cache=True, nogil=True)
def winner_take_all(acc, acc2, min_d, uniqueness, mode, disp, dint, conf):  # pragma: no cover - compiled
    """Per pixel: the best disparity of ``acc`` (WTA), its uniqueness and sub-pixel offset.

    dint[y, x] = best integer disparity, or -(1 << 30) where the match is not unique or the matching pixel is
    outside the right image: the best cost must be <= (1 - uniqueness) x the best cost at |k - k*| > 1.
    conf = 1 - best / second (0 .. 1). disp = float disparity with the sub-pixel offset from the costs at
    k* - 1, k*, k* + 1: mode 1 parabola, 2 equiangular (symmetric V), 0 none; NaN where dint is invalid.
    """
    H, W, D = acc.shape
    bad = -(1 << 30)
    for y in prange(H):
        a = np.empty(D, np.int32)
        for x in range(W):
            a1 = acc[y, x]
            a2 = acc2[y, x]
            for k in range(D):
                a[k] = np.int32(a1[k]) + np.int32(a2[k])
            kmax = min(D - 1, x - min_d)  # x - d >= 0
            if kmax < 0:
                dint[y, x] = bad
                disp[y, x] = np.nan
                conf[y, x] = 0.0
                continue
            best = np.int32(1 << 30)
            kb = 0
            for k in range(kmax + 1):
                v = np.int32(a[k])
                if v < best:
                    best = v
                    kb = k
            second = np.int32(1 << 30)
            for k in range(kmax + 1):
                if k < kb - 1 or k > kb + 1:
                    second = min(second, np.int32(a[k]))
            if second == np.int32(1 << 30):
                second = best
            c = 1.0 - best / second if second > 0 else 0.0
            conf[y, x] = c
            if best > (1.0 - uniqueness) * second:
                dint[y, x] = bad
                disp[y, x] = np.nan
                continue
            dint[y, x] = min_d + kb
            off = 0.0
            if mode > 0 and kb > 0 and kb < kmax:
                l = np.float32(a[kb - 1])
                m = np.float32(a[kb])
                r = np.float32(a[kb + 1])
                if mode == 1:
                    den = l - 2.0 * m + r
                    if den > 0:
                        off = 0.5 * (l - r) / den
                else:
                    den = (l - m) if l >= r else (r - m)
                    if den > 0:
                        off = 0.5 * (l - r) / den
                off = min(max(off, -0.5), 0.5)
            disp[y, x] = np.float32(min_d + kb + off)


@njit(parallel=True, cache=True, nogil=True)
def right_winner(acc, acc2, min_d, dright):  # pragma: no cover - compiled
    """dright[y, xr] = argmin_d acc[y, xr + d, d - min_d] (the right image's disparity from the same
    aggregated costs, Hirschmuller 2008 sec. 3.4); -(1 << 30) where no d keeps xr + d inside."""
    H, W, D = acc.shape
    for y in prange(H):
        for xr in range(W):
            best = np.int32(1 << 30)
            kb = -1
            for k in range(D):
                x = xr + min_d + k
                if x < 0:
                    continue
                if x >= W:
                    break
                v = np.int32(acc[y, x, k]) + np.int32(acc2[y, x, k])
                if v < best:
                    best = v
                    kb = k
            dright[y, xr] = min_d + kb if kb >= 0 else -(1 << 30)


@njit(parallel=True, cache=True, nogil=True)
def lr_check(dint, dright, max_diff, disp):  # pragma: no cover - compiled
    """Set disp to NaN where the left match x -> x - d is not confirmed by the right image's own best match
    (|dright[y, x - d] - d| > max_diff): occlusions and mismatches (Fusiello 12.6.2)."""
    H, W = dint.shape
    for y in prange(H):
        for x in range(W):
            d = dint[y, x]
            if d < -(1 << 29):
                continue
            xr = x - d
            if xr < 0 or xr >= W or abs(dright[y, xr] - d) > max_diff:
                disp[y, x] = np.nan


@njit(parallel=True, cache=True, nogil=True)
def median3(disp, out):  # pragma: no cover - compiled
    """3 x 3 median over the valid (non-NaN) neighbours of each valid pixel; invalid pixels stay NaN."""
    H, W = disp.shape
    for y in prange(H):
        buf = np.empty(9, np.float32)
        for x in range(W):
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
