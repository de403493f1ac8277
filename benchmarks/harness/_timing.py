"""The benchmarks' shared timer: the median of a few calls (run the benchmarks from the repo root)."""

from __future__ import annotations

import time

import numpy as np


def timed(fn, repeat: int = 3, *, warmup: int = 0):
    """(median seconds of ``repeat`` calls of ``fn`` after ``warmup`` untimed ones, the last result)."""
    for _ in range(warmup):
        fn()
    ts, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), out
