"""Fused census-SGM kernels (numba, int16 lanes): Hamming cost, 8-path aggregation, winner-take-all and the
left-right check in two raster passes, with one (H, W, D) int16 volume written once and read once.

Why it is laid out this way (issue 20):

- **int16 lanes.** Path costs satisfy ``L <= C + P2 <= 64 + 4000``, the sum of 8 paths ``<= 32512``, so every
  value fits int16. Each loop over the disparities stores int16 and only mixes int16 loads, so LLVM narrows
  numba's int64 arithmetic back to packed 16-bit ``vpminsw`` / ``vpaddw`` (``benchmarks/bench_stereo.py
  --asm`` counts them). The results are the exact integers of the float32 kernel they replace.
- **One loop per pixel.** :func:`step4` runs the 4 paths of a pass in one branch-free loop over the
  disparities (the two ends of the range read pad lanes of value ``_PAD`` instead of being special
  cases), stores their sum and takes each path's minimum in the same loop (a second loop over the stored
  row measured 3x slower); the jump term ``min L + P2`` is computed once per pixel, outside the loop.
- **Path starts are ordinary steps.** ``L = C`` where a path enters the image is the recurrence from an
  all-zero predecessor with minimum 0, so the buffers keep two zero rows (index 0 and W + 1) that the
  diagonal paths read past the image's sides.
- **Two passes, split at the middle row, fused with winner-take-all.** Task 0 runs the 4 forward paths
  (predecessors earlier in raster order) over rows ``[0, h)`` and stores their sum; task 1 runs the 4
  reverse paths over rows ``[h, H)`` (bottom up) and stores theirs. Then task 0 continues over rows
  ``[h, H)`` and task 1 over ``[0, h)``: each row's other half of S is already stored, so the row is
  complete as soon as it is aggregated and goes straight to winner-take-all, the right image's winner
  and the left-right check. The two tasks run on two threads when numba has two; the arithmetic is the
  same for any thread count (deterministic).

Layouts: census codes (H, W) uint64; path buffers (2 generations, 3 paths, W + 2, D + 2) int16 with pixel
``x`` at row ``x + 1`` and disparity index ``k`` at lane ``k + 1``; ``d = min_d + k``.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from rangekit.stereo._kernels import popcount

__all__ = ["sgm_match", "step", "step4"]

_PAD = 16000  # > any L; + P1 <= 4000 still fits int16
_BAD = -(1 << 30)
_NOKEY = np.int32(1 << 30)


@njit(inline="always")
def _rec(p, k, m, jump, ck, P1):  # pragma: no cover - compiled
    """The recurrence at lane k + 1 of a padded row ``p`` whose minimum is ``m`` (``jump = m + P2``)."""
    return np.int16(min(min(p[k + 1], np.int16(min(p[k], p[k + 2]) + P1)), jump) + ck - m)


@njit(inline="always")
def step(prev, pmin, c, cur, P1, P2):  # pragma: no cover - compiled
    """One SGM recurrence (Hirschmuller 2008, eq. 13) at one pixel, all disparities; returns min_k of the new L.

    prev, cur : (D + 2,) int16 with pad lanes 0 and D + 1 (value ``_PAD``); c : (D,) int16 matching cost.
    cur[k + 1] = c[k] + min(prev[k + 1], prev[k] + P1, prev[k + 2] + P1, pmin + P2) - pmin.
    """
    D = c.shape[0]
    jump = np.int16(pmin + P2)
    m = np.int16(32767)
    for k in range(D):
        v = _rec(prev, k, pmin, jump, c[k], P1)
        cur[k + 1] = v
        m = min(m, v)
    return m


@njit(inline="always")
def step4(ph, mh, pv, mv, pa, ma, pb, mb, c, ch, cv, ca, cb, e, o, P1, P2):  # pragma: no cover - compiled
    """:func:`step` for the 4 paths of one pass at once (horizontal, vertical, both diagonals) in one packed
    loop over the disparities, o[k] = their sum + e[k]; returns the 4 new minima. Measured 20 % faster than 4
    calls of :func:`step` and a sum loop: each cost lane is loaded once and each L lane stored once."""
    D = c.shape[0]
    jh = np.int16(mh + P2)
    jv = np.int16(mv + P2)
    ja = np.int16(ma + P2)
    jb = np.int16(mb + P2)
    nh = nv = na = nb = np.int16(32767)
    for k in range(D):
        ck = c[k]
        vh = _rec(ph, k, mh, jh, ck, P1)
        vv = _rec(pv, k, mv, jv, ck, P1)
        va = _rec(pa, k, ma, ja, ck, P1)
        vb = _rec(pb, k, mb, jb, ck, P1)
        ch[k + 1] = vh
        cv[k + 1] = vv
        ca[k + 1] = va
        cb[k + 1] = vb
        o[k] = np.int16(vh + vv + va + vb + e[k])
        nh = min(nh, vh)
        nv = min(nv, vv)
        na = min(na, va)
        nb = min(nb, vb)
    return nh, nv, na, nb


@njit(inline="always")
def _cost_row(cl, cr, y, min_d, invalid, rr, out):  # pragma: no cover - compiled
    """out[x, k] = popcount(cl[y, x] ^ cr[y, x - d]), d = min_d + k; ``invalid`` where x - d is outside.

    rr : (W + D - 1,) uint64 scratch: the right row reversed, rr[W - 1 - x + k] = cr[y, x - d] (clamped), so
    that the loop over k reads it forwards.
    """
    W = cl.shape[1]
    D = out.shape[1]
    for j in range(W + D - 1):
        rr[j] = cr[y, min(max(W - 1 - min_d - j, 0), W - 1)]
    for x in range(W):
        a = cl[y, x]
        hi = min(x - min_d, D - 1)  # k <= hi: x - d >= 0
        lo = max(x - min_d - W + 1, 0)  # k >= lo: x - d <= W - 1
        base = W - 1 - x
        o = out[x]
        for k in range(lo):
            o[k] = invalid
        ov = o[lo:]  # loops from 0 over views: numba drops the negative-index wraparound, LLVM packs them
        rv = rr[base + lo:]
        for k in range(hi + 1 - lo):
            ov[k] = np.int16(popcount(a ^ rv[k]))
        ov = o[max(hi + 1, lo):]
        for k in range(ov.shape[0]):
            ov[k] = invalid


@njit(cache=True, nogil=True)
def _wta_row(S, y, min_d, uniqueness, mode, max_diff, keys, rk, dint, dright, disp, conf):  # pragma: no cover
    """Winner-take-all, uniqueness, sub-pixel offset, the right image's winner and the left-right check on
    one row of the aggregated cost S (W, D) int16 (the rules of the float kernel this replaces, to the bit).

    Keys ``S * 256 + k`` make every argmin a packed minimum (ties go to the smaller k, as a first-minimum
    scan). keys : (D,) int32 scratch; rk : (W + D - 1,) int32 scratch for the right winner, indexed ``W - 1 - x + k``.
    """
    W, D = S.shape
    for j in range(W + D - 1):
        rk[j] = _NOKEY
    for x in range(W):
        a = S[x]
        base = W - 1 - x
        rv = rk[base:]
        key = _NOKEY
        for k in range(D):  # int32 keys; every (x, k) is a right-image candidate for xr = x - d
            kk = np.int32(a[k] * 256 + k)
            keys[k] = kk
            rv[k] = min(rv[k], kk)
            key = min(key, kk)
        kmax = min(D - 1, x - min_d)  # x - d >= 0
        if kmax < 0:
            dint[x] = _BAD
            disp[y, x] = np.nan
            conf[y, x] = 0.0
            continue
        if kmax < D - 1:  # near the left border: the best over the disparities that stay in the image
            key = _NOKEY
            for k in range(kmax + 1):
                key = min(key, keys[k])
        kb = key & 255
        best = key >> 8
        second = _NOKEY  # the best at |k - kb| > 1 (k is the key's low byte; masking, not storing, keeps
        lo = kb - 1  # the loop packed and free of store-forwarding stalls: measured 2x faster)
        hi = kb + 1
        for k in range(kmax + 1):
            kk = keys[k]
            j = kk & 255
            second = min(second, kk if (j < lo or j > hi) else _NOKEY)
        second = second >> 8 if second != _NOKEY else _NOKEY
        if second == _NOKEY:
            second = best
        conf[y, x] = 1.0 - best / second if second > 0 else 0.0
        if best > (1.0 - uniqueness) * second:
            dint[x] = _BAD
            disp[y, x] = np.nan
            continue
        dint[x] = min_d + kb
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
    n = rk.shape[0]
    for xr in range(W):
        j = W - 1 - min_d - xr
        kk = rk[j] if 0 <= j < n else _NOKEY
        dright[xr] = min_d + (kk & 255) if kk != _NOKEY else _BAD
    if max_diff >= 0:
        for x in range(W):
            d = dint[x]
            if d == _BAD:
                continue
            xr = x - d
            if xr < 0 or xr >= W or abs(dright[xr] - d) > max_diff:
                disp[y, x] = np.nan


@njit(cache=True, nogil=True)
def _pass(cl, cr, min_d, invalid, P1, P2, reverse, diagonals, i0, i1, Lb, Mb, vol, finish, uniqueness,
          mode, max_diff, disp, conf):  # pragma: no cover - compiled
    """Rows ``i0 <= i < i1`` of one raster pass (row y = i, or H - 1 - i when ``reverse``).

    Lb, Mb : the pass's path state (2, 3, W + 2, D + 2) int16 and (2, 3, W + 2) int16, generation i % 2 the
    previous row; zeroed data and ``_PAD`` pads before row 0, kept between the two calls of a pass.
    ``finish`` False: vol[y] = this pass's sum of L_r. True: S = that sum + vol[y] (the other pass), then
    :func:`_wta_row` into disp and conf.
    """
    H, W = cl.shape
    D = vol.shape[2]
    s = -1 if reverse else 1
    crow = np.empty((W, D), np.int16)
    srow = np.empty((W, D), np.int16)
    hb = np.full((2, D + 2), _PAD, np.int16)
    zero = np.full(D + 2, _PAD, np.int16)
    zero[1:D + 1] = 0
    zk = np.zeros(D, np.int16)
    rr = np.empty(W + D - 1, np.uint64)
    rk = np.empty(W + D - 1, np.int32)
    keys = np.empty(D, np.int32)
    dint = np.empty(W, np.int32)
    dright = np.empty(W, np.int32)
    for i in range(i0, i1):
        y = H - 1 - i if reverse else i
        _cost_row(cl, cr, y, min_d, invalid, rr, crow)
        p = i & 1
        q = 1 - p
        out = srow if finish else vol[y]
        hprev = zero
        hmin = np.int16(0)
        for j in range(W):
            x = W - 1 - j if reverse else j
            c = crow[x]
            hcur = hb[j & 1]
            xv = x + 1
            cv = Lb[q, 0, xv]
            o = out[x]
            if diagonals:
                a, b = xv - s, xv + s
                hmin, Mb[q, 0, xv], Mb[q, 1, xv], Mb[q, 2, xv] = step4(
                    hprev, hmin, Lb[p, 0, xv], Mb[p, 0, xv], Lb[p, 1, a], Mb[p, 1, a], Lb[p, 2, b], Mb[p, 2, b],
                    c, hcur, cv, Lb[q, 1, xv], Lb[q, 2, xv], vol[y, x] if finish else zk, o, P1, P2)
            else:
                hmin = step(hprev, hmin, c, hcur, P1, P2)
                Mb[q, 0, xv] = step(Lb[p, 0, xv], Mb[p, 0, xv], c, cv, P1, P2)
                e = vol[y, x] if finish else zk
                for k in range(D):
                    o[k] = np.int16(hcur[k + 1] + cv[k + 1] + e[k])
            hprev = hcur
        if finish:
            _wta_row(srow, y, min_d, uniqueness, mode, max_diff, keys, rk, dint, dright, disp, conf)


@njit(parallel=True, cache=True, nogil=True)
def sgm_match(cl, cr, min_d, D, invalid, P1, P2, diagonals, uniqueness, mode, max_diff, disp,
              conf):  # pragma: no cover - compiled
    """Census-SGM disparities of a rectified pair from its census codes.

    cl, cr : (H, W) uint64 census codes of the left and right image; d = min_d + k, k < D.
    invalid : int16 cost where x - d is outside the right image. P1, P2 : int16 penalties.
    diagonals : 8 paths (else 4). uniqueness, mode (0 none, 1 parabola, 2 equiangular), max_diff (< 0: no
    left-right check): as :func:`rangekit.stereo.sgm_disparity`.
    disp, conf : (H, W) float32 outputs, disparity (NaN where invalid) and 1 - best / second best.
    """
    H, W = cl.shape
    h = H // 2
    vol = np.empty((H, W, D), np.int16)
    Lb = np.full((2, 2, 3, W + 2, D + 2), _PAD, np.int16)
    Lb[:, :, :, :, 1:D + 1] = 0
    Mb = np.zeros((2, 2, 3, W + 2), np.int16)
    for t in prange(2):  # first halves: forward rows [0, h), reverse rows [h, H)
        _pass(cl, cr, min_d, invalid, P1, P2, t == 1, diagonals, 0, h if t == 0 else H - h, Lb[t], Mb[t],
              vol, False, uniqueness, mode, max_diff, disp, conf)
    for t in prange(2):  # second halves, each row finished by winner-take-all as soon as it is aggregated
        _pass(cl, cr, min_d, invalid, P1, P2, t == 1, diagonals, h if t == 0 else H - h, H, Lb[t], Mb[t],
              vol, True, uniqueness, mode, max_diff, disp, conf)
