"""Fused census-SGM kernels (numba, int16 lanes): Hamming cost, 8-path aggregation, winner-take-all and the
left-right check in two raster passes, with one (H, W, lanes) int16 volume written once and read once.

Why it is laid out this way (issue 20):

- **int16 lanes.** Path costs satisfy ``L <= C + P2 <= 64 + 4000``, the sum of 8 paths ``<= 32512``, so every
  value fits int16. Each loop over the disparities stores int16 and only mixes int16 loads, so LLVM narrows
  numba's int64 arithmetic back to packed 16-bit ``vpminsw`` / ``vpaddw`` (``benchmarks/stereo/bench_stereo.py
  --asm`` counts them). The results are the exact integers of the float32 kernel they replace.
- **One loop per pixel.** :func:`step4` runs the 4 paths of a pass in one branch-free loop over the
  disparities (the two ends of the range read pad lanes of value ``_PAD`` instead of being special
  cases), stores their sum and takes each path's minimum in the same loop (a second loop over the stored
  row measured 3x slower); the jump term ``min L + P2`` is computed once per pixel, outside the loop.
- **Rows compiled ``noalias``, pixels in pairs.** :func:`_row` aggregates one row and is compiled with
  :func:`rangekit._runtime.noalias.njit_noalias`: its arguments are distinct buffers (the previous and the current
  row's state, the horizontal path's two scratch rows, the cost, the other pass's sum, the output), so
  LLVM packs the disparity loop without checking at every pixel that 13 arrays do not overlap. Those
  checks, and reloading the addresses they compare, took more time than the loop itself: ``sgm_match``
  on the 640x400 benchmark pair went from 41 to 22 ms on one thread with the same disparities
  (``benchmarks/stereo/bench_stereo.py --parts``). Pixels go in pairs so that the horizontal path reads from one scratch argument and writes
  to the other (h1 -> h0, then h0 -> h1).
- **Lanes in whole registers.** The disparities are padded to ``lanes``, a multiple of 32 (one 512-bit
  register of int16): LLVM packs the loop by 32 and leaves the rest to scalar code, which made 48
  disparities slower than 64. A padded lane has cost ``_FAR`` = 12000, so its L stays in [12000, 16000],
  while a real lane's candidates are at most ``min L + P2 <= 4064 + 4000``: a padded lane never wins a
  minimum nor enters a real lane. Winner-take-all reads the D real lanes only.
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

Layouts: census codes (H, W) uint64; path buffers (2 generations, 3 paths, W + 2, lanes + 2) int16 with
pixel ``x`` at row ``x + 1`` and disparity index ``k`` at lane ``k + 1``; ``d = min_d + k``, k < D.
"""

from __future__ import annotations

import numpy as np
from numba import literally, njit, prange

from rangekit._runtime.noalias import njit_noalias
from rangekit.stereo._kernels import popcount

__all__ = ["sgm_match", "step4"]

_PAD = 16000  # the pad lanes 0 and lanes + 1; + P1 <= 4000 still fits int16
_LANES = 32  # the disparities are padded to a multiple of this many int16 lanes (one 512-bit register)
_FAR = 12000  # the cost of the padded disparities: their L stays in [12000, 16000], no real lane reaches it
_BAD = -(1 << 30)
_NOKEY = np.int32(1 << 30)


@njit(inline="always")
def _rec(p, k, m, jump, ck, P1):  # pragma: no cover - compiled
    """The recurrence at lane k + 1 of a padded row ``p`` whose minimum is ``m`` (``jump = m + P2``)."""
    return np.int16(min(min(p[k + 1], np.int16(min(p[k], p[k + 2]) + P1)), jump) + ck - m)


@njit(inline="always")
def step4(ph, mh, pv, mv, pa, ma, pb, mb, c, ch, cv, ca, cb, e, o, P1, P2, diagonals):  # pragma: no cover
    """One SGM recurrence (Hirschmuller 2008, eq. 13) for the paths of one pass at one pixel, all
    disparities, in one packed loop: horizontal (h), vertical (v) and, when ``diagonals`` (a compile-time
    constant), both diagonals (a, b). With n = c.shape[0] (the padded lanes), path r reads its previous L
    ``p_r`` (n + 2,) int16 with pad lanes 0 and n + 1 (value ``_PAD``) and minimum ``m_r``, and writes its
    new L into ``c_r``:

        c_r[k + 1] = c[k] + min(p_r[k + 1], p_r[k] + P1, p_r[k + 2] + P1, m_r + P2) - m_r

    c : (n,) int16 matching cost; o[k] = the paths' sum + e[k]. Returns the new minima (h, v, a, b; a and
    b are 0 without diagonals). One loop for all paths: each cost lane is loaded once, each L lane stored
    once (measured 20 % faster than one loop per path and a sum loop).
    """
    D = c.shape[0]
    jh = np.int16(mh + P2)
    jv = np.int16(mv + P2)
    ja = np.int16(ma + P2)
    jb = np.int16(mb + P2)
    nh = nv = np.int16(32767)
    na = nb = np.int16(32767 if diagonals else 0)
    for k in range(D):
        ck = c[k]
        vh = _rec(ph, k, mh, jh, ck, P1)
        vv = _rec(pv, k, mv, jv, ck, P1)
        ch[k + 1] = vh
        cv[k + 1] = vv
        nh = min(nh, vh)
        nv = min(nv, vv)
        if diagonals:
            va = _rec(pa, k, ma, ja, ck, P1)
            vb = _rec(pb, k, mb, jb, ck, P1)
            ca[k + 1] = va
            cb[k + 1] = vb
            o[k] = np.int16(vh + vv + va + vb + e[k])
            na = min(na, va)
            nb = min(nb, vb)
        else:
            o[k] = np.int16(vh + vv + e[k])
    return nh, nv, na, nb


@njit(inline="always")
def _cost_row(cl, cr, y, min_d, D, invalid, rr, out):  # pragma: no cover - compiled
    """out[x, k] = popcount(cl[y, x] ^ cr[y, x - d]), d = min_d + k, k < D; ``invalid`` where x - d is
    outside. out : (W, lanes) int16; its lanes from D on are left as they are.

    rr : (W + D - 1,) uint64 scratch: the right row reversed, rr[W - 1 - x + k] = cr[y, x - d] (clamped), so
    that the loop over k reads it forwards.
    """
    W = cl.shape[1]
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
        ov = o[max(hi + 1, lo):D]
        for k in range(ov.shape[0]):
            ov[k] = invalid


@njit(cache=True, nogil=True)
def _wta_row(S, y, min_d, uniqueness, mode, max_diff, keys, rk, dint, dright, disp, conf):  # pragma: no cover
    """Winner-take-all, uniqueness, sub-pixel offset, the right image's winner and the left-right check on
    one row of the aggregated cost S (W, lanes) int16, disparities k < D (the rules of the float kernel this
    replaces, to the bit).

    Keys ``S * 256 + k`` make every argmin a packed minimum (ties go to the smaller k, as a first-minimum
    scan). keys : (D,) int32 scratch; rk : (W + D - 1,) int32 scratch for the right winner, indexed ``W - 1 - x + k``.
    """
    W = S.shape[0]
    D = keys.shape[0]
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


@njit(inline="always")
def _pixel(x, s, diagonals, crow, hp, hmin, hc, Lp, Mp, Lc, Mc, e, o, P1, P2):  # pragma: no cover - compiled
    """:func:`step4` at pixel x: the horizontal path from ``hp`` (minimum ``hmin``) into ``hc``, the others
    from the previous row Lp, Mp into Lc, Mc; o[x] = their sum + e[x]. Returns the new horizontal minimum."""
    xv = x + 1
    a, b = (xv - s, xv + s) if diagonals else (xv, xv)
    hmin, Mc[0, xv], Mc[1, xv], Mc[2, xv] = step4(
        hp, hmin, Lp[0, xv], Mp[0, xv], Lp[1, a], Mp[1, a], Lp[2, b], Mp[2, b], crow[x], hc, Lc[0, xv],
        Lc[1, xv], Lc[2, xv], e[x], o[x], P1, P2, diagonals)
    return hmin


@njit_noalias(cache=True, nogil=True)
def _row(crow, Lp, Mp, Lc, Mc, h0, h1, e, o, reverse, diagonals, P1, P2):  # pragma: no cover - compiled
    """One row of a pass: o = e + the sum of its paths' L over the row, Lc, Mc = the row's path state.

    crow : (W, lanes) int16 cost. Lp, Mp / Lc, Mc : the previous / this row's state (3, W + 2, lanes + 2)
    and (3, W + 2). h0, h1 : (lanes + 2,) scratch for the horizontal path. e, o : (W, lanes) int16.
    Compiled ``noalias``: every argument must be a distinct buffer. Pixels go in pairs so that the
    horizontal path's previous and current L are always two different arguments (h1 then h0, h0 then h1).
    """
    literally(diagonals)  # compiled once per value: the 4-path loop does not carry the diagonals' code
    W, lanes = crow.shape
    s = -1 if reverse else 1
    h0[:] = _PAD  # pad lanes of both; h1 starts the path: an all-zero predecessor with minimum 0
    h1[:] = _PAD
    h1[1:lanes + 1] = 0
    hmin = np.int16(0)
    for j in range(0, W - 1, 2):
        x0, x1 = (W - 1 - j, W - 2 - j) if reverse else (j, j + 1)
        hmin = _pixel(x0, s, diagonals, crow, h1, hmin, h0, Lp, Mp, Lc, Mc, e, o, P1, P2)
        hmin = _pixel(x1, s, diagonals, crow, h0, hmin, h1, Lp, Mp, Lc, Mc, e, o, P1, P2)
    if W & 1:
        _pixel(0 if reverse else W - 1, s, diagonals, crow, h1, hmin, h0, Lp, Mp, Lc, Mc, e, o, P1, P2)


@njit(cache=True, nogil=True)
def _pass(cl, cr, min_d, D, invalid, P1, P2, reverse, diagonals, i0, i1, Lb, Mb, vol, finish, uniqueness,
          mode, max_diff, disp, conf):  # pragma: no cover - compiled
    """Rows ``i0 <= i < i1`` of one raster pass (row y = i, or H - 1 - i when ``reverse``).

    Lb, Mb : the pass's path state (2, 3, W + 2, lanes + 2) int16 and (2, 3, W + 2) int16, generation i % 2 the
    previous row; zeroed data and ``_PAD`` pads before row 0, kept between the two calls of a pass.
    ``finish`` False: vol[y] = this pass's sum of L_r. True: S = that sum + vol[y] (the other pass), then
    :func:`_wta_row` into disp and conf.
    """
    H, W = cl.shape
    lanes = vol.shape[2]
    crow = np.full((W, lanes), _FAR, np.int16)
    srow = np.empty((W, lanes), np.int16)
    zrow = np.zeros((W, lanes), np.int16)
    hb = np.empty((2, lanes + 2), np.int16)
    rr = np.empty(W + D - 1, np.uint64)
    rk = np.empty(W + D - 1, np.int32)
    keys = np.empty(D, np.int32)
    dint = np.empty(W, np.int32)
    dright = np.empty(W, np.int32)
    for i in range(i0, i1):
        y = H - 1 - i if reverse else i
        _cost_row(cl, cr, y, min_d, D, invalid, rr, crow)
        p = i & 1
        e, o = (vol[y], srow) if finish else (zrow, vol[y])
        if diagonals:
            _row(crow, Lb[p], Mb[p], Lb[1 - p], Mb[1 - p], hb[0], hb[1], e, o, reverse, True, P1, P2)
        else:
            _row(crow, Lb[p], Mb[p], Lb[1 - p], Mb[1 - p], hb[0], hb[1], e, o, reverse, False, P1, P2)
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
    lanes = -(-D // _LANES) * _LANES
    vol = np.empty((H, W, lanes), np.int16)
    Lb = np.full((2, 2, 3, W + 2, lanes + 2), _PAD, np.int16)
    Lb[:, :, :, :, 1:lanes + 1] = 0
    Mb = np.zeros((2, 2, 3, W + 2), np.int16)
    for t in prange(2):  # first halves: forward rows [0, h), reverse rows [h, H)
        _pass(cl, cr, min_d, D, invalid, P1, P2, t == 1, diagonals, 0, h if t == 0 else H - h, Lb[t], Mb[t],
              vol, False, uniqueness, mode, max_diff, disp, conf)
    for t in prange(2):  # second halves, each row finished by winner-take-all as soon as it is aggregated
        _pass(cl, cr, min_d, D, invalid, P1, P2, t == 1, diagonals, h if t == 0 else H - h, H, Lb[t], Mb[t],
              vol, True, uniqueness, mode, max_diff, disp, conf)
