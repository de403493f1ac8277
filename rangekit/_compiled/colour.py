"""Compiled colour mapping (numba; cached on disk): :func:`rangekit.colour.colourise` in one pass.

The same float64 operations in the same order as the formula ``table[rint(255 clip((v - vmin) / span, 0, 1))]``
(no fused multiply-add, round half to even), so the bytes are numpy's: one pass over a 1.3 Mpx map instead of
eight (a float64 copy, subtract, divide, clip, scale, round, cast, gather): 6.5 ms instead of 20 for a 1280x1024
float64 map on one core (``benchmarks/app/bench_report.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["colour_indices"]


@njit(cache=True, nogil=True)
def colour_indices(values, vmin, span, table, out):  # pragma: no cover - compiled
    """``out[i] = table[k]`` (``table`` (257, 3) uint8, entry 256 the NaN colour) for each of ``values`` (N,)
    float32 or float64: k = rint(255 clip((v - vmin) / span, 0, 1)); span <= 0: k = 255 where v > vmin else 0;
    a non-finite v: k = 256."""
    for i in range(values.shape[0]):
        t = np.float64(values[i])
        if not np.isfinite(t):
            k = 256
        else:
            if span > 0:
                t = (t - vmin) / span
            else:
                t = 1.0 if t > vmin else 0.0
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            k = int(np.rint(t * 255))
        out[i, 0] = table[k, 0]
        out[i, 1] = table[k, 1]
        out[i, 2] = table[k, 2]
