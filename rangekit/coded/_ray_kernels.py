"""Compiled ray-ray triangulation and its along-ray Jacobian, one pass per point (numba; cached on disk).

In numpy the midpoints of the common perpendiculars and then
:func:`rangekit.coded.uncertainty.along_ray_jacobian` (a LAPACK inverse of each 2x2 distortion Jacobian
among them) made about 50 passes over the decoded points: 0.3 CPU-s a view at 1280x1024 (issue 20). Here
each point is done at once with the same formulas in the same order (no fused multiply-add; numpy's
einsum order for the dot products): the same points, bit for bit. The 2x2 inverse is the closed form
rather than LAPACK's (last bits of the float64 derivative; the float32 sigma came out identical on the
simulated 12-view scan).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from rangekit._compiled.lens import distort_jacobian_point

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["ray_ray_points"]


@njit(cache=True, nogil=True, inline="always")
def _gain(m0, m1, Rg, a0, a1, a2, e0, e1, e2, w0x, w0y, w0z, ss, tt, a12, a22, det):  # pragma: no cover - compiled
    """Derivative along the unit camera ray (a) of the midpoint when the projector ray (e, unnormalised)
    turns by Rg [m0, m1, 0] (one column of the inverse distortion Jacobian over the focal length)."""
    g0 = m0 * Rg[0, 0] + m1 * Rg[0, 1]
    g1 = m0 * Rg[1, 0] + m1 * Rg[1, 1]
    g2 = m0 * Rg[2, 0] + m1 * Rg[2, 1]
    ee = a0 * g0 + a1 * g1 + a2 * g2
    r1 = ee * tt
    r2 = (g0 * w0x + g1 * w0y + g2 * w0z) + ee * ss - 2 * (e0 * g0 + e1 * g1 + e2 * g2) * tt
    ds = (a22 * r1 + a12 * r2) / det
    dt = (a12 * r1 + r2) / det
    return 0.5 * (ds + dt * a12 + tt * ee)


@njit(parallel=True, cache=True, nogil=True, error_model="numpy")
def ray_ray_points(valid, row_start, dirs, o1, d2, o2, xy, kp, dist, Rg,
                   xyz, residual, proj_xy, gains):  # pragma: no cover - compiled
    """Ray-ray triangulation of the decoded pixels of an (H, W) view and the along-ray derivatives of each point.

    valid : (H, W) bool decoded pixels, row_start (H + 1,) the number of them before each row; dirs :
    (H * W, 3) world unit directions of the camera's pixel rays, from ``o1`` (3,); d2 : (N, 3) the
    projector's rays (unit, world, row-major over the valid pixels) from ``o2`` through the undistorted
    normalised projector coordinates ``xy`` (N, 2). kp : (fx, fy, cx, cy) of the projector, dist its 12
    OpenCV coefficients, Rg its rotation to world.
    Outputs, organised, NaN where no point (undecoded, or rays that do not meet in front of both): xyz
    (H, W, 3) midpoints of the common perpendicular (world metres), residual (H, W) its length, proj_xy
    (H, W, 2) = xy, gains (H, W, 2) metres per projector pixel along the unit camera ray for the column and
    the row (rangekit.coded.uncertainty.along_ray_jacobian). The dot products are summed as numpy's einsum
    sums three terms, ``(p0 + p2) + p1``.
    """
    nan = np.nan
    H, W = valid.shape
    w0x, w0y, w0z = o1[0] - o2[0], o1[1] - o2[1], o1[2] - o2[2]
    for y in prange(H):
        i = row_start[y]
        for x in range(W):
            xyz[y, x, 0] = xyz[y, x, 1] = xyz[y, x, 2] = residual[y, x] = nan
            proj_xy[y, x, 0] = proj_xy[y, x, 1] = gains[y, x, 0] = gains[y, x, 1] = nan
            if not valid[y, x]:
                continue
            proj_xy[y, x, 0], proj_xy[y, x, 1] = xy[i, 0], xy[i, 1]
            k = y * W + x
            a0, a1, a2 = dirs[k, 0], dirs[k, 1], dirs[k, 2]
            b0, b1, b2 = d2[i, 0], d2[i, 1], d2[i, 2]
            b = (a0 * b0 + a2 * b2) + a1 * b1
            dd = (a0 * w0x + a2 * w0z) + a1 * w0y
            e = (b0 * w0x + b2 * w0z) + b1 * w0y
            denom = 1.0 - b * b
            s = (b * e - dd) / denom
            t = (e - b * dd) / denom
            if s > 0 and t > 0 and denom > 1e-12:
                p0, p1, p2 = o1[0] + s * a0, o1[1] + s * a1, o1[2] + s * a2
                q0, q1, q2 = o2[0] + t * b0, o2[1] + t * b1, o2[2] + t * b2
                xyz[y, x, 0] = 0.5 * (p0 + q0)
                xyz[y, x, 1] = 0.5 * (p1 + q1)
                xyz[y, x, 2] = 0.5 * (p2 + q2)
                r0, r1, r2 = p0 - q0, p1 - q1, p2 - q2
                residual[y, x] = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                gains[y, x, 0], gains[y, x, 1] = _gains(a0, a1, a2, xy[i, 0], xy[i, 1], w0x, w0y, w0z, kp, dist,
                                                        Rg)
            i += 1


@njit(cache=True, nogil=True, inline="always")
def _gains(a0, a1, a2, x, y, w0x, w0y, w0z, kp, dist, Rg):  # pragma: no cover - compiled
    """uncertainty.along_ray_jacobian of one point: camera ray a (renormalised), projector coordinates (x, y)."""
    na = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / na, a1 / na, a2 / na
    e0 = x * Rg[0, 0] + y * Rg[0, 1] + Rg[0, 2]
    e1 = x * Rg[1, 0] + y * Rg[1, 1] + Rg[1, 2]
    e2 = x * Rg[2, 0] + y * Rg[2, 1] + Rg[2, 2]
    a12 = a0 * e0 + a1 * e1 + a2 * e2
    a22 = e0 * e0 + e1 * e1 + e2 * e2
    det = a22 - a12 * a12
    d1w = a0 * w0x + a1 * w0y + a2 * w0z
    d2w = e0 * w0x + e1 * w0y + e2 * w0z
    ss = (a12 * d2w - a22 * d1w) / det
    tt = (d2w - a12 * d1w) / det
    j00, j01, j10, j11 = distort_jacobian_point(x, y, dist)
    jd = j00 * j11 - j01 * j10
    g_col = _gain(j11 / jd / kp[0], -j10 / jd / kp[0], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y, w0z, ss, tt, a12,
                  a22, det)
    g_row = _gain(-j01 / jd / kp[1], j00 / jd / kp[1], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y, w0z, ss, tt, a12,
                  a22, det)
    return g_col, g_row
