"""Compiled along-ray Jacobian of ray-ray triangulation, one pass per point (numba; cached on disk).

:func:`rangekit.coded.uncertainty.along_ray_jacobian` in numpy made about 30 passes over the decoded
points, a LAPACK inverse of each 2x2 distortion Jacobian among them: 0.2 CPU-s a view at 1280x1024
(issue 20). Here each point is done at once with the same formulas in the same order (no fused
multiply-add); the 2x2 inverse is the closed form rather than LAPACK's (last bits of the float64
derivative; the float32 sigma came out identical on the simulated 12-view scan).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from rangekit._lens_kernels import distort_jacobian_point

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["ray_ray_gains"]


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
def ray_ray_gains(d1, o1, o2, xy, kp, dist, Rg, gains):  # pragma: no cover - compiled
    """Along-ray derivatives of N ray-ray points (rangekit.coded.uncertainty.along_ray_jacobian, the same
    formulas in the same order).

    d1 : (N, 3) world directions of the camera rays from ``o1`` (3,); xy : (N, 2) undistorted normalised
    projector coordinates, from the projector's centre ``o2``; kp : (fx, fy, cx, cy) of the projector, dist
    its 12 OpenCV coefficients, Rg its rotation to world. gains (N, 2) out: metres per projector pixel
    along the unit camera ray for the column and the row.
    """
    w0x, w0y, w0z = o1[0] - o2[0], o1[1] - o2[1], o1[2] - o2[2]
    for i in prange(d1.shape[0]):
        a0, a1, a2 = d1[i, 0], d1[i, 1], d1[i, 2]
        x, y = xy[i, 0], xy[i, 1]
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
        gains[i, 0] = _gain(j11 / jd / kp[0], -j10 / jd / kp[0], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y, w0z,
                            ss, tt, a12, a22, det)
        gains[i, 1] = _gain(-j01 / jd / kp[1], j00 / jd / kp[1], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y, w0z,
                            ss, tt, a12, a22, det)
