"""Compiled OpenCV lens model (numba; cached on disk): the distortion and its Jacobian of one point, and the
Newton passes of :func:`rangekit.lens.undistort`.

The scalar functions are the same operations in the same order as :func:`rangekit.lens.distort` and
``_distort_jacobian`` (no fused multiply-add), so the compiled undistortion gives numpy's bits: one pass
per Newton step instead of about twenty numpy passes (issue 20).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

# OpenMP or numba's own workqueue; skips the TBB probe (and its warning where TBB is too old).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["distort_point", "distort_jacobian_point", "distort_points", "newton_pass", "newton_check"]


@njit(cache=True, nogil=True, inline="always")
def distort_point(x, y, d):  # pragma: no cover - compiled
    """rangekit.lens.distort of one point (d: the 12 coefficients), the same operations."""
    k1, k2, p1, p2, k3, k4, k5, k6 = d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]
    s1, s2, s3, s4 = d[8], d[9], d[10], d[11]
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
    return xd, yd


@njit(cache=True, nogil=True, inline="always")
def distort_jacobian_point(x, y, d):  # pragma: no cover - compiled
    """rangekit.lens._distort_jacobian of one point: (j00, j01, j10, j11), the same operations."""
    k1, k2, p1, p2, k3, k4, k5, k6 = d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7]
    s1, s2, s3, s4 = d[8], d[9], d[10], d[11]
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    radial = num / den
    drad = (dnum * den - num * dden) / (den * den)
    j00 = radial + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * s1 * x + 4 * s2 * r2 * x
    j01 = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * s1 * y + 4 * s2 * r2 * y
    j10 = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * s3 * x + 4 * s4 * r2 * x
    j11 = radial + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * s3 * y + 4 * s4 * r2 * y
    return j00, j01, j10, j11


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def distort_points(xy, d, out):  # pragma: no cover - compiled
    """``out`` (N, 2) = rangekit.lens.distort of every point of ``xy`` (N, 2), numpy's bits (NaN stays NaN)."""
    for i in prange(xy.shape[0]):
        out[i, 0], out[i, 1] = distort_point(xy[i, 0], xy[i, 1], d)


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def newton_pass(xy, target, d, out, res):  # pragma: no cover - compiled
    """One Newton step of every point (N, 2): ``res[i]`` = max |distort(xy[i]) - target[i]| (NaN ignored,
    0 if both are NaN), ``out`` = xy after the closed-form 2x2 step (rangekit.lens.undistort)."""
    for i in prange(xy.shape[0]):
        x, y = xy[i, 0], xy[i, 1]
        fx, fy = distort_point(x, y, d)
        rx = fx - target[i, 0]
        ry = fy - target[i, 1]
        m = 0.0
        if abs(rx) > m:
            m = abs(rx)
        if abs(ry) > m:
            m = abs(ry)
        res[i] = m
        j00, j01, j10, j11 = distort_jacobian_point(x, y, d)
        det = j00 * j11 - j01 * j10
        out[i, 0] = x - (j11 * rx - j01 * ry) / det
        out[i, 1] = y - (j00 * ry - j10 * rx) / det


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def newton_check(xy, target, d, limit):  # pragma: no cover - compiled
    """NaN the points whose residual max |distort(xy) - target| is not below ``limit`` (or is NaN)."""
    for i in prange(xy.shape[0]):
        fx, fy = distort_point(xy[i, 0], xy[i, 1], d)
        rx = abs(fx - target[i, 0])
        ry = abs(fy - target[i, 1])
        m = rx if rx > ry else ry
        if rx != rx or ry != ry or not m < limit:
            xy[i, 0] = np.nan
            xy[i, 1] = np.nan
