"""Compiled ray-ray triangulation with its along-ray Jacobian, one pass per pixel (numba; cached on disk).

The numpy path (undo the projector's distortion by vectorised Newton, build both rays, the midpoint of
their common perpendicular, then the derivatives of :func:`rangekit.coded.uncertainty.along_ray_jacobian`)
made about 40 full passes over the decoded pixels and cost 0.5 CPU-s a view at 1280x1024 (issue 20). Here
each pixel is done at once, with the same formulas in the same order (no fused multiply-add); the only
differences are that Newton stops per pixel (numpy stopped when the worst pixel converged, so a pixel may
take one step more or less: the last bit of its normalised coordinate, 1e-16) and the 2x2 inverse is the
closed form rather than LAPACK's.
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]

__all__ = ["ray_ray_points"]


@njit(cache=True, nogil=True, inline="always")
def _distort(x, y, d):  # pragma: no cover - compiled
    """rangekit.camera.distort of one point, the same operations."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], d[8],
                                                      d[9], d[10], d[11])
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
    return xd, yd


@njit(cache=True, nogil=True, inline="always")
def _jacobian(x, y, d):  # pragma: no cover - compiled
    """rangekit.camera._distort_jacobian of one point: (j00, j01, j10, j11)."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], d[8],
                                                      d[9], d[10], d[11])
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


@njit(cache=True, nogil=True, inline="always")
def _undistort(xd, yd, d, distorted, tol, max_iter):  # pragma: no cover - compiled
    """rangekit.camera.undistort of one point (Newton, closed-form 2x2 step); NaN if it does not converge."""
    x, y = xd, yd
    if distorted:
        for _ in range(max_iter):
            fx, fy = _distort(x, y, d)
            rx, ry = fx - xd, fy - yd
            if not max(abs(rx), abs(ry)) >= tol:
                break
            j00, j01, j10, j11 = _jacobian(x, y, d)
            det = j00 * j11 - j01 * j10
            x -= (j11 * rx - j01 * ry) / det
            y -= (j00 * ry - j10 * rx) / det
        fx, fy = _distort(x, y, d)
        if not max(abs(fx - xd), abs(fy - yd)) < 1e3 * tol:
            return np.nan, np.nan
    return x, y


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
def ray_ray_points(cols, rows, dirs, o1, kp, d, distorted, R, Rg, o2, tol, max_iter,
                   xyz, residual, proj_xy, gains):  # pragma: no cover - compiled
    """Ray-ray triangulation of every pixel with a decoded (column, row), and the along-ray derivatives.

    cols, rows : (H, W) float decoded projector coordinates (NaN where undecoded).
    dirs : (H * W, 3) world unit directions of the camera's pixel rays, from ``o1`` (3,).
    kp : (fx, fy, cx, cy) of the projector; d : its 12 OpenCV coefficients (``distorted``: any non-zero);
    R : (3, 3) its rotation to world (scale divided out, as transform_vectors), Rg the same as given (for the
    derivatives, as along_ray_jacobian), o2 its centre. tol, max_iter : Newton's (rangekit.camera.undistort).
    Outputs (NaN where no point): xyz (H, W, 3) world metres, residual (H, W) metres, proj_xy (H, W, 2)
    undistorted normalised projector coordinates, gains (H, W, 2) metres per projector pixel along the
    unit camera ray for the column and the row (rangekit.coded.uncertainty.along_ray_jacobian).
    """
    H, W = cols.shape
    nan = np.nan
    w0x, w0y, w0z = o1[0] - o2[0], o1[1] - o2[1], o1[2] - o2[2]
    for yy in prange(H):
        for xx in range(W):
            u = np.float64(cols[yy, xx])
            v = np.float64(rows[yy, xx])
            for k in range(3):
                xyz[yy, xx, k] = nan
            residual[yy, xx] = nan
            proj_xy[yy, xx, 0] = nan
            proj_xy[yy, xx, 1] = nan
            gains[yy, xx, 0] = nan
            gains[yy, xx, 1] = nan
            if not (np.isfinite(u) and np.isfinite(v)):
                continue
            x, y = _undistort((u - kp[2]) / kp[0], (v - kp[3]) / kp[1], d, distorted, tol, max_iter)
            proj_xy[yy, xx, 0] = x
            proj_xy[yy, xx, 1] = y
            i = yy * W + xx
            a0, a1, a2 = dirs[i, 0], dirs[i, 1], dirs[i, 2]
            # projector ray: [x, y, 1] normalised, rotated to world (rays_from_normalized)
            nrm = np.sqrt(x * x + y * y + 1.0)
            cx, cy, cz = x / nrm, y / nrm, 1.0 / nrm
            b0 = cx * R[0, 0] + cy * R[0, 1] + cz * R[0, 2]
            b1 = cx * R[1, 0] + cy * R[1, 1] + cz * R[1, 2]
            b2 = cx * R[2, 0] + cy * R[2, 1] + cz * R[2, 2]
            b = a0 * b0 + a1 * b1 + a2 * b2
            dd = a0 * w0x + a1 * w0y + a2 * w0z
            e = b0 * w0x + b1 * w0y + b2 * w0z
            denom = 1.0 - b * b
            s = (b * e - dd) / denom
            t = (e - b * dd) / denom
            if not (s > 0 and t > 0 and denom > 1e-12):
                continue
            p0, p1, p2 = o1[0] + s * a0, o1[1] + s * a1, o1[2] + s * a2
            q0, q1, q2 = o2[0] + t * b0, o2[1] + t * b1, o2[2] + t * b2
            xyz[yy, xx, 0] = 0.5 * (p0 + q0)
            xyz[yy, xx, 1] = 0.5 * (p1 + q1)
            xyz[yy, xx, 2] = 0.5 * (p2 + q2)
            r0, r1, r2 = p0 - q0, p1 - q1, p2 - q2
            residual[yy, xx] = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
            # along-ray derivatives (uncertainty.along_ray_jacobian): unit camera ray, unnormalised projector ray
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
            j00, j01, j10, j11 = _jacobian(x, y, d)
            jd = j00 * j11 - j01 * j10
            gains[yy, xx, 0] = _gain(j11 / jd / kp[0], -j10 / jd / kp[0], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y,
                                     w0z, ss, tt, a12, a22, det)
            gains[yy, xx, 1] = _gain(-j01 / jd / kp[1], j00 / jd / kp[1], Rg, a0, a1, a2, e0, e1, e2, w0x, w0y,
                                     w0z, ss, tt, a12, a22, det)
