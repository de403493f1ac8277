"""Compiled loops of the motion check of binary codes (:mod:`rangekit.coded.motion.check`; numba, cached on disk)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["MAX_TURN_BACK", "crossing_residuals", "flag_bracketed", "level_crossings", "tile_unread"]

#: The largest step back (codes) that counts as codes turning back; a longer one is a depth edge. A step back of
#: one code next to a step of one is the noise at a stripe edge (c, c+1, c), not motion.
MAX_TURN_BACK = 8


@njit(cache=True, nogil=True, inline="always")
def _diff(stack, p_by_bit, i_by_bit, b, y, x, transposed):  # pragma: no cover - compiled
    """Pattern minus inverse of bit ``b`` at (y, x) of the (possibly transposed) code map."""
    if transposed:
        return np.float32(stack[p_by_bit[b], x, y]) - np.float32(stack[i_by_bit[b], x, y])
    return np.float32(stack[p_by_bit[b], y, x]) - np.float32(stack[i_by_bit[b], y, x])


@njit(cache=True, nogil=True)
def _misread(stack, p_by_bit, i_by_bit, words, nb, y, xa, ca, cb, m, weak, transposed):  # pragma: no cover - compiled
    """Whether the step from code ``ca`` at pixel ``xa`` to ``cb`` at ``xa + 1`` (row ``y``; codes with their ``m``
    finest bits masked off, ``c >> m``) is one the noise can make: every frame bit in which the two codes differ has
    ``|pattern - inverse| < weak`` on both pixels (those bits are not read there, so the step says nothing about
    where their stripes lie)."""
    differ = (words[ca << m] ^ words[cb << m]) >> m << m
    for b in range(m, nb):
        if (differ >> b) & 1:
            for j in range(2):
                if abs(_diff(stack, p_by_bit, i_by_bit, b, y, xa + j, transposed)) >= weak:
                    return False
    return True


@njit(parallel=True, cache=True, nogil=True)
def level_crossings(stack, code, level, t_fine, p_by_bit, i_by_bit, edge_bit, transposed, out
                    ):  # pragma: no cover - compiled
    """Stripe-edge crossings of the codes with each pixel's ``level`` finest bits masked off (``code >> level``).

    ``code`` (H, W) int32 integer codes (-1 invalid), ``level`` (H, W) int8; ``t_fine`` (H, W-1) the crossings of
    the codes themselves (rangekit.coded._kernels.crossings), taken where the level is 0; ``stack``, ``p_by_bit``,
    ``i_by_bit``, ``edge_bit``, ``transposed`` as :func:`crossing_residuals`'s. ``out`` (H, W-1) float32: between
    pixels x and x+1 of one level whose masked codes differ by one, the fraction of the way where the pattern and
    inverse of the bit that changes cross (the Gray code of ``c >> m`` is that of ``c`` without its m finest bits,
    so its edge between ``a`` and ``a + 1`` is the edge of bit ``edge_bit[((a + 1) << m) - 1]``); NaN elsewhere."""
    H, W = code.shape
    for y in prange(H):
        for x in range(W - 1):
            out[y, x] = np.nan
            m = level[y, x]
            c0 = code[y, x]
            c1 = code[y, x + 1]
            if c0 < 0 or c1 < 0 or level[y, x + 1] != m:
                continue
            if m == 0:
                out[y, x] = t_fine[y, x]
                continue
            a = c0 >> m
            b = c1 >> m
            if a - b != 1 and b - a != 1:
                continue
            bit = edge_bit[((min(a, b) + 1) << m) - 1]
            d0 = _diff(stack, p_by_bit, i_by_bit, bit, y, x, transposed)
            d1 = _diff(stack, p_by_bit, i_by_bit, bit, y, x + 1, transposed)
            if d0 * d1 <= 0 and d0 != d1:
                out[y, x] = d0 / (d0 - d1)


@njit(parallel=True, cache=True, nogil=True)
def crossing_residuals(code, level, t, max_gap, stack, p_by_bit, i_by_bit, edge_bit, words, weak, transposed,
                       res, lo):  # pragma: no cover - compiled
    """Each stripe-edge crossing's disagreement with the code changes on either side of it along the row.

    ``code`` (H, W) int32 integer codes (-1 invalid); ``level`` (H, W) int8: each pixel's code is checked with its
    ``level`` finest bits masked off (``code >> level``: bits the capture does not read there), pixels of two
    levels not compared; ``t`` (H, W-1) float32 crossings between pixels x and x+1 of those codes
    (:func:`level_crossings`; NaN: none). ``stack`` the capture ((K, H, W), or (K, W, H) of the
    transposed maps: ``transposed``), ``p_by_bit``/``i_by_bit`` each bit's pattern and inverse frame,
    ``edge_bit[c]`` the bit that changes between codes c and c+1, ``words[c]`` the frame bits of code c (which
    frames are brighter than their inverses), ``weak``: a bit whose pattern and inverse differ by less than this
    (grey levels) is read no better than the noise. For each crossing (a step of one code between neighbours),
    the previous and the next change of code along the row, each within ``max_gap`` pixels and with no invalid
    pixel between:

    - a crossing whose bit's pattern - inverse changes across its pixel pair by less than ``weak`` is located no
      better than the noise lets (``weak`` = k noise sigmas: to sqrt(2) / k of a pixel or worse): every residual
      it takes part in is NaN;
    - either neighbouring change goes the other way by 2 to :data:`MAX_TURN_BACK` codes (the codes turn back:
      ``c+1, c, c+3, c+2``, bits from two surfaces): ``res = inf``, unless the bits that step differs in are
      read below ``weak`` on both its pixels (:func:`_misread`: the noise's step, not a move), then NaN;
    - both are steps of one the same way (edges c-1|c, c|c+1, c+1|c+2): ``res[y, x] = (pos - (pos_prev +
      pos_next) / 2) / s``, s the camera pixels per code between the outer two (signed), so the offset is in
      codes: 0 up to noise where the three stripes were projected onto one surface, the shift between the frames
      where they were not;
    - otherwise NaN. ``lo[y, x]`` = the lower code of the crossing where ``res`` is set (of the whole code: the
      last code under the edge, ``((a + 1) << level) - 1`` for masked codes a | a + 1), else -1.

    Codes, steps and residuals are in masked codes (units of ``1 << level`` codes).
    """
    H, W = code.shape
    nb = p_by_bit.shape[0]
    for y in prange(H):
        pos = np.empty(W, np.float64)     # each change of code along the row: where, which way, from which code
        step = np.empty(W, np.int64)
        low = np.empty(W, np.int64)
        at = np.empty(W, np.int64)
        run = np.empty(W, np.int64)       # changes with no invalid pixel between them share a run number
        sure = np.empty(W, np.bool_)      # a crossing located better than the noise
        px = np.empty(W, np.int64)        # the pixel before the change
        n = 0
        r = 0
        for x in range(W - 1):
            res[y, x] = np.nan
            lo[y, x] = -1
            m = level[y, x]
            if code[y, x] < 0 or code[y, x + 1] < 0 or level[y, x + 1] != m:
                r += 1
                continue
            c0 = code[y, x] >> m
            c1 = code[y, x + 1] >> m
            if c0 != c1:
                tt = t[y, x]
                pos[n] = x + (tt if tt == tt else 0.5)
                step[n] = c1 - c0
                low[n] = (((c0 if c0 < c1 else c1) + 1) << m) - 1     # the edge's lower code, unmasked
                at[n] = x if tt == tt else -1
                run[n] = r
                sure[n] = True
                px[n] = x
                if tt == tt:
                    b = edge_bit[low[n]]
                    slope = (_diff(stack, p_by_bit, i_by_bit, b, y, x + 1, transposed)
                             - _diff(stack, p_by_bit, i_by_bit, b, y, x, transposed))
                    sure[n] = abs(slope) >= weak
                n += 1
        for k in range(1, n - 1):
            if at[k] < 0:
                continue
            if run[k - 1] != run[k] or run[k + 1] != run[k]:
                continue
            if pos[k] - pos[k - 1] > max_gap or pos[k + 1] - pos[k] > max_gap:
                continue
            back_a = step[k - 1] * step[k] < 0 and 2 <= abs(step[k - 1]) <= MAX_TURN_BACK
            back_b = step[k + 1] * step[k] < 0 and 2 <= abs(step[k + 1]) <= MAX_TURN_BACK
            if back_a or back_b:
                misread = False
                for kk in (k - 1, k + 1):
                    if (kk == k - 1 and back_a) or (kk == k + 1 and back_b):
                        xa = px[kk]
                        m = level[y, xa]
                        ca = code[y, xa] >> m
                        cb = code[y, xa + 1] >> m
                        if _misread(stack, p_by_bit, i_by_bit, words, nb, y, xa, ca, cb, m, weak, transposed):
                            misread = True
                if not misread:
                    res[y, at[k]] = np.inf
                    lo[y, at[k]] = low[k]
            elif (abs(step[k - 1]) == 1 and abs(step[k + 1]) == 1 and at[k - 1] >= 0 and at[k + 1] >= 0
                  and sure[k - 1] and sure[k] and sure[k + 1]):
                s = (pos[k + 1] - pos[k - 1]) / (step[k - 1] + step[k + 1])
                res[y, at[k]] = (pos[k] - 0.5 * (pos[k - 1] + pos[k + 1])) / s
                lo[y, at[k]] = low[k]


@njit(parallel=True, cache=True, nogil=True)
def flag_bracketed(t, res, limit, out):  # pragma: no cover - compiled
    """``out[y, x]`` = True where a crossing bracketing pixel x along its row (the last one before it or the first
    one after it) has ``|res| > limit``: its stripe edge was displaced, so the pixel's interpolated code is."""
    H, W = out.shape
    for y in prange(H):
        bad_left = False
        for x in range(W):
            out[y, x] = bad_left
            if x < W - 1 and t[y, x] == t[y, x]:
                bad_left = abs(res[y, x]) > limit
        bad_right = False
        for x in range(W - 1, -1, -1):
            if x < W - 1 and t[y, x] == t[y, x]:
                bad_right = abs(res[y, x]) > limit
            out[y, x] = out[y, x] or bad_right



@njit(parallel=True, cache=True, nogil=True)
def tile_unread(stack, p_by_bit, i_by_bit, decoded, weak, tile_y, tile_x, counts):  # pragma: no cover - compiled
    """Each tile's count of decoded pixels and of those where each bit is read below ``weak``.

    ``stack`` (K, H, W) the capture; ``p_by_bit``/``i_by_bit`` each bit's pattern and inverse frame; ``decoded``
    (H, W) bool; ``weak`` grey levels; tiles of ``tile_y`` x ``tile_x`` pixels. ``counts`` (tiles down, tiles
    across, 1 + nb) int64: ``[ty, tx, 0]`` the decoded pixels of the tile, ``[ty, tx, 1 + b]`` those where
    ``|pattern - inverse|`` of bit ``b`` is under ``weak``."""
    H, W = decoded.shape
    nty, ntx, _ = counts.shape
    nb = p_by_bit.shape[0]
    for ty in prange(nty):
        for tx in range(ntx):
            for j in range(nb + 1):
                counts[ty, tx, j] = 0
        for y in range(ty * tile_y, min(H, (ty + 1) * tile_y)):
            for x in range(W):
                if decoded[y, x]:
                    counts[ty, x // tile_x, 0] += 1
            for b in range(nb):
                P = stack[p_by_bit[b], y]
                I = stack[i_by_bit[b], y]
                for x in range(W):
                    if decoded[y, x] and abs(np.float32(P[x]) - np.float32(I[x])) < weak:
                        counts[ty, x // tile_x, 1 + b] += 1

