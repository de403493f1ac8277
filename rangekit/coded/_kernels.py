"""Compiled inner loops of the coded-light decoder (numba; compiled once, cached on disk).

Why numba: decoding is a per-pixel recurrence over 20-40 frames, and subpixel edges need, for each pixel,
the nearest stripe crossing on either side. In numpy that is about 30 full-image passes per axis
(0.6 s at 2048x1500); one fused loop per image row reads each frame row once (see docs/benchmarks.md).
All kernels walk memory row by row; parallel loops are over rows or over blocks of columns.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

# OpenMP or numba's own workqueue; skips the TBB probe (and its warning where TBB is too old).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["gray_rows", "masks_rows", "crossings", "smooth_along", "interp_along_rows", "interp_along_cols",
           "range_filter_normals"]


@njit(parallel=True, cache=True, nogil=True)
def gray_rows(stack, p_idx, i_idx, lut, size, code, tie_bit=0):  # pragma: no cover - compiled
    """code[y, x] = binary column of the Gray code read MSB first from frames p_idx[j] > i_idx[j] (``tie_bit``
    where they are equal); -1 if >= size."""
    K, H, W = stack.shape
    nb = p_idx.shape[0]
    for y in prange(H):
        g = np.zeros(W, np.int32)
        for j in range(nb):
            P = stack[p_idx[j], y]
            I = stack[i_idx[j], y]
            for x in range(W):
                g[x] = (g[x] << 1) | (1 if P[x] > I[x] else (tie_bit if P[x] == I[x] else 0))
        for x in range(W):
            c = lut[g[x]]
            code[y, x] = c if c < size else -1


@njit(parallel=True, cache=True, nogil=True)
def masks_rows(stack, white_i, black_i, sep_p, sep_i, t_shadow, t_low, ratio, inv_fs,
               conf, shadow, low, glob_mask, direct, glob):  # pragma: no cover - compiled
    """Shadow / low-contrast masks, confidence (white - black) / fs, and direct/global separation from
    the pattern/inverse pairs sep_p/sep_i (best contrast wins): direct = |P - I|, global = 2 (min - black)."""
    K, H, W = stack.shape
    ns = sep_p.shape[0]
    for y in prange(H):
        Wr = stack[white_i, y]
        Br = stack[black_i, y]
        for x in range(W):
            span = np.float32(Wr[x]) - np.float32(Br[x])
            if span < 0:
                span = 0.0
            sh = span < t_shadow
            shadow[y, x] = sh
            lo = (span < t_low) and not sh
            low[y, x] = lo
            conf[y, x] = span * inv_fs
            best_d = -1.0
            best_min = 0.0
            for j in range(ns):
                p = np.float32(stack[sep_p[j], y, x])
                q = np.float32(stack[sep_i[j], y, x])
                d = abs(p - q)
                if d > best_d:
                    best_d = d
                    best_min = min(p, q)
            if ns > 0:
                g = 2.0 * (best_min - np.float32(Br[x]))
                if g < 0:
                    g = 0.0
                direct[y, x] = best_d * inv_fs
                glob[y, x] = g * inv_fs
                glob_mask[y, x] = (not sh) and (not lo) and g > ratio * best_d
            else:
                glob_mask[y, x] = False


@njit(parallel=True, cache=True, nogil=True)
def crossings(stack, code, p_by_bit, i_by_bit, edge_bit, vertical, out, min_bit=0):  # pragma: no cover - compiled
    """Stripe-edge crossings between neighbouring pixels whose codes differ by one.

    vertical == False: pairs (y, x)-(y, x+1), out (H, W-1); True: pairs (y, x)-(y+1, x), out (H-1, W).
    out = t in [0, 1], the fraction of the way from the first pixel to the crossing of pattern and
    inverse of the frame whose stripes change between the two codes; NaN where there is none, or where
    that frame's bit is below ``min_bit`` (edges of finer stripes left out).
    """
    Ho = out.shape[0]
    Wo = out.shape[1]
    dy = 1 if vertical else 0
    for y in prange(Ho):
        y1 = y + dy
        for x in range(Wo):
            x1 = x + 1 - dy
            c0 = code[y, x]
            c1 = code[y1, x1]
            t = np.nan
            if c0 >= 0 and c1 >= 0 and (c1 - c0 == 1 or c0 - c1 == 1):
                lo = c0 if c0 < c1 else c1
                b = edge_bit[lo]
                if b >= min_bit:
                    d0 = np.float32(stack[p_by_bit[b], y, x]) - np.float32(stack[i_by_bit[b], y, x])
                    d1 = np.float32(stack[p_by_bit[b], y1, x1]) - np.float32(stack[i_by_bit[b], y1, x1])
                    if d0 * d1 <= 0 and d0 != d1:
                        t = d0 / (d0 - d1)
            out[y, x] = t


@njit(parallel=True, cache=True, nogil=True)
def smooth_along(coord, taps, max_step, vertical, out):  # pragma: no cover - compiled
    """``coord`` (H, W) float32 averaged with ``taps`` (2 h + 1, float64, summing to 1) along camera columns
    (``vertical``) or rows, summed in float64 in tap order; the pixel's own value where a tap is outside the
    image, NaN or over ``max_step`` per pixel of distance off it (:func:`rangekit.coded.binary.smooth_along_stripes`)."""
    H, W = coord.shape
    n = taps.shape[0]
    half = n // 2
    dy = 1 if vertical else 0
    for y in prange(H):
        for x in range(W):
            c = np.float64(coord[y, x])
            acc = 0.0
            kept = c == c
            for k in range(n if kept else 0):
                yy = np.int64(y) + (k - half) * dy
                xx = np.int64(x) + (k - half) * (1 - dy)
                v = np.float64(coord[yy, xx]) if 0 <= yy < H and 0 <= xx < W else np.nan
                if not (v == v) or abs(v - c) > max_step * abs(k - half):
                    kept = False
                    break
                acc += taps[k] * v
            out[y, x] = np.float32(acc) if kept else coord[y, x]


@njit(cache=True, nogil=True, inline="always")
def _interp(code, x, xl, ul, xr, ur, max_gap):  # pragma: no cover - compiled
    span = xr - xl
    du = ur - ul
    if span <= 0 or span > max_gap or abs(du) < 0.5 or abs(du) > 3.0:
        return np.nan
    u = ul + (x - xl) * du / span
    if abs(u - code) > 1.0:
        return np.nan
    return u


@njit(parallel=True, cache=True, nogil=True)
def interp_along_rows(code, t, max_gap, out):  # pragma: no cover - compiled
    """Subpixel value of each pixel from the crossings t (H, W-1) on either side along its row."""
    H, W = code.shape
    for y in prange(H):
        pos = np.empty(W, np.float32)
        val = np.empty(W, np.float32)
        pair = np.empty(W, np.int64)
        n = 0
        for x in range(W - 1):
            tt = t[y, x]
            if tt == tt:  # not NaN
                c0 = code[y, x]
                c1 = code[y, x + 1]
                pos[n] = x + tt
                val[n] = (c0 if c0 < c1 else c1) + 0.5
                pair[n] = x
                n += 1
        k = 0
        for x in range(W):
            while k < n and pair[k] < x:
                k += 1
            r = np.nan
            if k >= 1 and k < n and code[y, x] >= 0:
                r = _interp(code[y, x], x, pos[k - 1], val[k - 1], pos[k], val[k], max_gap)
            out[y, x] = r


@njit(parallel=True, cache=True, nogil=True)
def interp_along_cols(code, t, max_gap, out):  # pragma: no cover - compiled
    """As interp_along_rows, along columns: crossings t (H-1, W). Blocks of columns sweep down, recording
    the row of the last crossing above each pixel, then up, interpolating with the first one below."""
    H, W = code.shape
    block = 64
    nblocks = (W + block - 1) // block
    for bi in prange(nblocks):
        x0 = bi * block
        x1 = min(W, x0 + block)
        bw = x1 - x0
        up = np.empty((H, bw), np.int32)  # row of the crossing pair above (pair y-1 or earlier), -1 if none
        last = np.full(bw, -1, np.int32)
        for y in range(H):
            if y >= 1:
                for j in range(bw):
                    if t[y - 1, x0 + j] == t[y - 1, x0 + j]:
                        last[j] = y - 1
            for j in range(bw):
                up[y, j] = last[j]
        nxt = np.full(bw, -1, np.int32)
        for y in range(H - 1, -1, -1):
            if y <= H - 2:
                for j in range(bw):
                    if t[y, x0 + j] == t[y, x0 + j]:
                        nxt[j] = y
            for j in range(bw):
                x = x0 + j
                r = np.nan
                a = up[y, j]
                b = nxt[j]
                c = code[y, x]
                if c >= 0 and a >= 0 and b >= 0:
                    ca0, ca1 = code[a, x], code[a + 1, x]
                    cb0, cb1 = code[b, x], code[b + 1, x]
                    r = _interp(c, y, a + t[a, x], (ca0 if ca0 < ca1 else ca1) + 0.5,
                                b + t[b, x], (cb0 if cb0 < cb1 else cb1) + 0.5, max_gap)
                out[y, x] = r


@njit(cache=True, nogil=True, inline="always")
def _decoded(y, x, code_c, code_r, has_c, has_r, shadow, low, glob_mask):  # pragma: no cover - compiled
    if shadow[y, x] or low[y, x] or glob_mask[y, x]:
        return False
    if has_c and code_c[y, x] < 0:
        return False
    if has_r and code_r[y, x] < 0:
        return False
    return True


@njit(parallel=True, cache=True, nogil=True)
def finalise_binary(code_c, sub_c, code_r, sub_r, has_c, has_r, use_sub, shadow, low, glob_mask, conf,
                    proj_col, proj_row, incons):  # pragma: no cover - compiled
    """Combine codes, subpixel values and masks into the outputs in one pass (NaN where rejected).

    ``incons``: on an otherwise accepted pixel, a code outside the projector or (with ``use_sub``) no
    subpixel value (no stripe edge on both sides within max_gap, or edges that disagree with the code)
    at the border of the decoded region. Inside it (all 4 neighbours lit and decoded, e.g. where stripes
    are narrower than a camera pixel) such pixels keep their integer code.
    """
    H, W = shadow.shape
    nan = np.float32(np.nan)
    for y in prange(H):
        for x in range(W):
            reject = shadow[y, x] or low[y, x] or glob_mask[y, x]
            bad = (has_c and code_c[y, x] < 0) or (has_r and code_r[y, x] < 0)
            miss_c = use_sub and has_c and not (sub_c[y, x] == sub_c[y, x])
            miss_r = use_sub and has_r and not (sub_r[y, x] == sub_r[y, x])
            if (miss_c or miss_r) and not bad:
                interior = y > 0 and y < H - 1 and x > 0 and x < W - 1
                if interior:
                    interior = _decoded(y - 1, x, code_c, code_r, has_c, has_r, shadow, low, glob_mask) and \
                        _decoded(y + 1, x, code_c, code_r, has_c, has_r, shadow, low, glob_mask) and \
                        _decoded(y, x - 1, code_c, code_r, has_c, has_r, shadow, low, glob_mask) and \
                        _decoded(y, x + 1, code_c, code_r, has_c, has_r, shadow, low, glob_mask)
                bad = not interior
            inc = bad and not reject
            incons[y, x] = inc
            if reject or bad:
                proj_col[y, x] = nan
                proj_row[y, x] = nan
                conf[y, x] = 0.0
                continue
            if has_c:
                proj_col[y, x] = np.float32(code_c[y, x]) if (miss_c or not use_sub) else sub_c[y, x]
            else:
                proj_col[y, x] = nan
            if has_r:
                proj_row[y, x] = np.float32(code_r[y, x]) if (miss_r or not use_sub) else sub_r[y, x]
            else:
                proj_row[y, x] = nan
            if miss_c or miss_r:
                conf[y, x] *= 0.5


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def range_filter_normals(xyz, vp, max_jump, min_neighbours, margin, extra, use_extra,
                         out, normals):  # pragma: no cover - compiled
    """Flying-pixel filter and normals of an organised (H, W, 3) range map in compiled passes, the same
    numbers as ``discontinuity_mask`` + ``range_normals`` of :mod:`rangekit.coded.triangulate` (same
    operations in the same order, no fused multiply-add): ``out`` = ``xyz`` with NaN where dropped (or where
    ``extra`` is True, when ``use_extra``), ``normals`` those of ``out`` facing ``vp``, NaN where undefined."""
    H, W = xyz.shape[0], xyz.shape[1]
    r = np.empty((H, W))
    for y in prange(H):
        for x in range(W):
            a = xyz[y, x, 0] - vp[0]
            b = xyz[y, x, 1] - vp[1]
            c = xyz[y, x, 2] - vp[2]
            r[y, x] = np.sqrt(a * a + b * b + c * c)
    bad = np.empty((H, W), np.bool_)  # dropped by the jump test or invalid
    for y in prange(H):
        for x in range(W):
            ry = r[y, x]
            if not np.isfinite(ry):
                bad[y, x] = True
                continue
            lim = max_jump * ry
            jump = False
            nv = 0
            for k in range(4):
                yy = y + (-1, 1, 0, 0)[k]
                xx = x + (0, 0, -1, 1)[k]
                if 0 <= yy < H and 0 <= xx < W:
                    q = r[yy, xx]
                    if np.isfinite(q):
                        nv += 1
                        if np.abs(q - ry) > lim:
                            jump = True
            bad[y, x] = jump or nv < min_neighbours
    drop = bad
    if margin > 0:  # square dilation of `bad`, outside the image counting as bad (scipy's border_value=1)
        rows = np.empty((H, W), np.bool_)
        for y in prange(H):
            for x in range(W):
                v = x - margin < 0 or x + margin >= W
                for xx in range(max(0, x - margin), min(W, x + margin + 1)):
                    v = v or bad[y, xx]
                rows[y, x] = v
        drop = np.empty((H, W), np.bool_)
        for y in prange(H):
            for x in range(W):
                v = y - margin < 0 or y + margin >= H
                for yy in range(max(0, y - margin), min(H, y + margin + 1)):
                    v = v or rows[yy, x]
                drop[y, x] = v
    for y in prange(H):
        for x in range(W):
            gone = drop[y, x] or (use_extra and extra[y, x])
            for k in range(3):
                out[y, x, k] = np.nan if gone else xyz[y, x, k]
    for y in prange(H):
        for x in range(W):
            if y == 0 or y == H - 1 or x == 0 or x == W - 1:
                for k in range(3):
                    normals[y, x, k] = np.nan
                continue
            ax = out[y, x + 1, 0] - out[y, x - 1, 0]
            ay = out[y, x + 1, 1] - out[y, x - 1, 1]
            az = out[y, x + 1, 2] - out[y, x - 1, 2]
            bx = out[y + 1, x, 0] - out[y - 1, x, 0]
            by = out[y + 1, x, 1] - out[y - 1, x, 1]
            bz = out[y + 1, x, 2] - out[y - 1, x, 2]
            n0 = ay * bz - az * by
            n1 = az * bx - ax * bz
            n2 = ax * by - ay * bx
            s = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            n0 /= s
            n1 /= s
            n2 /= s
            f = n0 * (vp[0] - out[y, x, 0]) + n1 * (vp[1] - out[y, x, 1]) + n2 * (vp[2] - out[y, x, 2])
            if f < 0:
                n0, n1, n2 = -n0, -n1, -n2
            normals[y, x, 0] = n0
            normals[y, x, 1] = n1
            normals[y, x, 2] = n2


@njit(cache=True, nogil=True)  # called per chunk on the decoder's threads
def phase_correct(phase, offset, out, slope):  # pragma: no cover - compiled
    """PhaseCorrection.__call__ and .slope of a (h, w) float32 phase in one pass, the same float32 operations
    (rangekit.coded.response): ``out`` the true phase in [0, 2 pi), ``slope`` d(true) / d(measured)."""
    two_pi = np.float32(2 * np.pi)
    m = offset.size - 1
    scale = np.float32(m / (2 * np.pi))
    one = np.float32(1.0)
    for y in range(phase.shape[0]):
        for x in range(phase.shape[1]):
            ph = phase[y, x]
            if not (ph >= 0 and ph < two_pi):  # np.mod is the identity on [0, 2 pi): skip its fmod there
                ph = np.mod(ph, two_pi)
            t = ph * scale
            if not t >= 0:  # NaN (numpy's table look-up would fail): never from atan2 of finite sums
                out[y, x] = slope[y, x] = np.float32(np.nan)
                continue
            i = min(np.int32(t), m - 1)
            f = t - np.float32(i)
            v = ph + offset[i] * (one - f) + offset[i + 1] * f
            out[y, x] = v if (v >= 0 and v < two_pi) else np.mod(v, two_pi)
            slope[y, x] = one + (offset[i + 1] - offset[i]) * scale


@njit(cache=True, nogil=True)  # called per chunk on the decoder's threads
def phase_sums(stack, idx, r0, sn, cs, S, C, A, alt):  # pragma: no cover - compiled
    """Sums of N phase-shifted frames ``stack[idx[s]]`` over rows r0 .. r0 + h, float32 in the order of
    rangekit.coded.phase.phase_from_steps and _noise_variance: S = sum sn[s] I_s, C = sum cs[s] I_s,
    A = sum I_s, alt = sum (-1)^s I_s (all (h, W))."""
    n = idx.shape[0]
    for y in range(S.shape[0]):
        for x in range(S.shape[1]):
            s_ = np.float32(0.0)
            c_ = np.float32(0.0)
            a_ = np.float32(0.0)
            l_ = np.float32(0.0)
            for s in range(n):
                f = np.float32(stack[idx[s], r0 + y, x])
                s_ = s_ + sn[s] * f
                c_ = c_ + cs[s] * f
                a_ = a_ + f
                l_ = l_ + f if s % 2 == 0 else l_ - f
            S[y, x] = s_
            C[y, x] = c_
            A[y, x] = a_
            alt[y, x] = l_
