"""Single-shot decoding of de Bruijn colour stripes (Fusiello 13.2.5; see rangekit.coded.patterns).

1. Each pixel's colour is normalised by its brightest channel (cancels albedo and shading of grey
   surfaces) and classified to the nearest palette colour.
2. Each camera row is cut into runs of one colour (all rows at once, on the flattened image); runs shorter
   than ``min_run`` pixels (blurred transitions) are dropped and equal neighbours merged.
3. Consecutive runs give transitions ``s = (c_i - c_{i-1} - 1) mod (k + 1)``; every window of n
   transitions is looked up in B(k, n), which names the stripe; the stripe's known colour must match.
4. The projector column inside a stripe is interpolated linearly between the run's two boundaries
   (midpoints between the last pixel of one colour and the first of the next).

Accuracy is that of the run boundaries, about a quarter of a camera pixel; for metrology use a temporal
code (hybrid, graycode). Confidence is the colour margin of the classification.
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import DecodeError
from rangekit.coded.patterns import DEBRUIJN_PALETTE, PatternSpec, de_bruijn, debruijn_stripe_colours
from rangekit.coded.result import DecodeResult

__all__ = ["decode_debruijn"]


def decode_debruijn(stack, spec: PatternSpec, *, min_contrast: float = 0.03, shadow_threshold: float = 0.02,
                    full_scale: float | None = None, min_run: int = 2) -> DecodeResult:
    """Decode one RGB capture of a ``debruijn`` spec. Returns a DecodeResult (columns only)."""
    frames = list(stack) if not isinstance(stack, np.ndarray) or stack.ndim == 4 else [stack]
    if len(frames) != 1:
        raise DecodeError(f"found {len(frames)} captures, pattern 'debruijn' is single-shot and needs 1")
    img = np.asarray(frames[0])
    if img.ndim != 3 or img.shape[2] != 3:
        raise DecodeError(f"de Bruijn decoding needs an RGB capture (H, W, 3), found shape {img.shape}; "
                          "capture with a colour camera")
    H, W, _ = img.shape
    fs = float(full_scale if full_scale is not None else (255 if img.dtype == np.uint8 else 65535))
    o = spec.options
    k, n, w = int(o["k"]), int(o["n"]), int(o["stripe_width"])
    palette = DEBRUIJN_PALETTE[: k + 1].astype(np.float32)
    n_stripes = -(-spec.width // w)
    stripe_colour = debruijn_stripe_colours(k, n, n_stripes)

    # 1. Classify colours.
    f = img.astype(np.float32)
    bright = f.max(axis=2)
    shadow = bright < shadow_threshold * fs
    low = ~shadow & (bright < min_contrast * fs)
    chroma = f / np.maximum(bright, 1.0)[:, :, None]
    d2 = ((chroma[:, :, None, :] - palette[None, None]) ** 2).sum(axis=3)  # (H, W, k+1)
    label = d2.argmin(axis=2).astype(np.int32)
    d_sorted = np.sort(d2, axis=2)
    margin = np.clip((d_sorted[:, :, 1] - d_sorted[:, :, 0]) / 1.0, 0, 1)
    label[shadow | low] = -1

    # 2. Runs along rows (flattened; a row start always begins a new run).
    flat = label.ravel()
    x = np.tile(np.arange(W), H)
    change = np.ones(flat.size, bool)
    change[1:] = (flat[1:] != flat[:-1]) | (x[1:] == 0)
    starts = np.flatnonzero(change)
    ends = np.r_[starts[1:], flat.size]  # exclusive
    run_lab = flat[starts]
    keep = (run_lab >= 0) & (ends - starts >= min_run)
    starts, ends, run_lab = starts[keep], ends[keep], run_lab[keep]
    row = starts // W
    # Merge neighbours of equal colour in the same row (a dropped blip inside one stripe).
    same = np.r_[False, (run_lab[1:] == run_lab[:-1]) & (row[1:] == row[:-1]) & (starts[1:] - ends[:-1] <= min_run)]
    g_start = np.minimum.reduceat(starts, np.flatnonzero(~same)) if len(starts) else starts
    g_end = np.maximum.reduceat(ends, np.flatnonzero(~same)) if len(ends) else ends
    g_lab = run_lab[~same]
    g_row = row[~same]
    m = len(g_lab)
    # Neighbouring runs are "adjacent" if in the same row and separated by at most a blurred transition.
    adj = np.r_[False, (g_row[1:] == g_row[:-1]) & (g_start[1:] - g_end[:-1] <= 3)] if m else np.zeros(0, bool)

    # 3. Transitions and windows of n of them.
    s = np.full(m, -1, np.int64)
    if m > 1:
        s[1:] = np.where(adj[1:], (g_lab[1:] - g_lab[:-1] - 1) % (k + 1), -1)
    seq = np.array(de_bruijn(k, n), dtype=np.int64)
    table = np.full(k ** n, -1, np.int64)
    win_codes = sum(seq[(np.arange(len(seq)) + q) % len(seq)] * k ** q for q in range(n))
    table[win_codes] = np.arange(len(seq))
    cands = np.full((n, m), -1, np.int64)
    for back in range(n):  # window starting at run a - back assigns stripe j + 1 + back to run a
        a = np.arange(m) - back
        ok = (a >= 1) & (a + n - 1 < m)
        code = np.zeros(m, np.int64)
        valid = ok.copy()
        for q in range(n):
            idx = np.clip(a + q, 0, m - 1)
            valid &= s[idx] >= 0
            code += np.where(ok, s[idx], 0) * k ** q
        j = np.where(valid, table[np.clip(code, 0, len(table) - 1)], -1)
        t = np.where(j >= 0, j + 1 + back, -1)
        good = (t >= 0) & (t < n_stripes)
        good &= stripe_colour[np.clip(t, 0, n_stripes - 1)] == g_lab
        cands[back, good] = t[good]
    # A run is decoded when every window covering it that decodes names the same stripe.
    has = cands >= 0
    first = np.where(has.any(axis=0), cands.max(axis=0), -1)
    agree = np.all(~has | (cands == first), axis=0)
    stripe = np.where(agree & (has.sum(axis=0) >= min(2, n)), first, -1)

    # 4. Columns inside each decoded run.
    col = np.full(H * W, np.nan, np.float32)
    ok_runs = np.flatnonzero(stripe >= 0)
    lengths = (g_end - g_start)[ok_runs]
    pix = np.repeat(g_start[ok_runs], lengths) + (np.arange(lengths.sum()) - np.repeat(np.cumsum(lengths) - lengths, lengths))
    frac = (pix - np.repeat(g_start[ok_runs], lengths) + 0.5) / np.repeat(lengths, lengths)
    col[pix] = (np.repeat(stripe[ok_runs], lengths) * w - 0.5 + frac * w).astype(np.float32)
    col = col.reshape(H, W)
    valid = np.isfinite(col)
    return DecodeResult(proj_col=col, proj_row=np.full((H, W), np.nan, np.float32),
                        confidence=np.where(valid, margin, 0).astype(np.float32), shadow=shadow, low_contrast=low,
                        global_dominated=np.zeros((H, W), bool), inconsistent=~valid & ~shadow & ~low,
                        white=img)
