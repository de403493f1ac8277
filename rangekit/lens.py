"""The OpenCV lens model (``cv2.projectPoints``' distortion) on normalised image coordinates: :func:`distort`, its
Jacobian, and :func:`undistort`, its exact inverse by Newton's method. Coefficients ``(k1, k2, p1, p2[, k3[, k4,
k5, k6[, s1, s2, s3, s4]]]])``; :class:`rangekit.camera.PinholeCamera` checks them and the zero tilt. Large arrays
run compiled (:mod:`rangekit._compiled.lens`), the same operations in the same order: numpy's bits.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distort", "distort_jacobian", "undistort", "COMPILED_DISTORT_POINTS"]

_N_COEFFS = 12  # k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4


def _full_coeffs(dist: np.ndarray) -> np.ndarray:
    return np.concatenate([dist[:_N_COEFFS], np.zeros(_N_COEFFS - min(len(dist), _N_COEFFS))])


#: From this many points :func:`distort` runs compiled (:func:`rangekit._compiled.lens.distort_points`, the same
#: bits): one pass instead of about twenty numpy passes, 1.7 CPU-ms instead of 12 for 200k points on one core.
COMPILED_DISTORT_POINTS = 4096


def distort(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Apply OpenCV distortion to (N, 2) normalised image coordinates (x/z, y/z); returns (N, 2)."""
    d = _full_coeffs(np.asarray(dist, dtype=np.float64))
    if len(xy) >= COMPILED_DISTORT_POINTS:
        from rangekit._compiled import lens as LK

        xy = np.ascontiguousarray(xy, dtype=np.float64)
        out = np.empty_like(xy)
        LK.distort_points(xy, d, out)
        return out
    return _distort_numpy(xy, d)


def _distort_numpy(xy: np.ndarray, d: np.ndarray) -> np.ndarray:
    """:func:`distort` in numpy (``d``: the 12 coefficients): the formula the compiled kernel follows."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
    return np.column_stack([xd, yd])


def _distort_jacobian(xy: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 2, 2) Jacobian of :func:`distort` with respect to (x, y)."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d
    x, y = xy[:, 0], xy[:, 1]
    r2 = x * x + y * y
    num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
    dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
    radial = num / den
    drad = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    J = np.empty((len(x), 2, 2))
    J[:, 0, 0] = radial + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x + 2 * s1 * x + 4 * s2 * r2 * x
    J[:, 0, 1] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * s1 * y + 4 * s2 * r2 * y
    J[:, 1, 0] = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y + 2 * s3 * x + 4 * s4 * r2 * x
    J[:, 1, 1] = radial + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x + 2 * s3 * y + 4 * s4 * r2 * y
    return J


def distort_jacobian(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N, 2, 2) Jacobian of :func:`distort` at (N, 2) normalised coordinates (x/z, y/z)."""
    return _distort_jacobian(np.asarray(xy, dtype=np.float64), _full_coeffs(np.asarray(dist, dtype=np.float64)))


def undistort(xy_distorted: np.ndarray, dist: np.ndarray, *, tol: float = 1e-14,
              max_iterations: int = 30) -> np.ndarray:
    """Invert :func:`distort` by Newton's method, vectorised over points.

    Parameters
    ----------
    xy_distorted : (N, 2) float64
        Distorted normalised coordinates, ``K^-1 [u, v, 1]``.
    dist : (M,) OpenCV distortion coefficients.
    tol : float
        Stop when every point's residual ``|distort(xy) - xy_distorted|`` is below this (normalised units;
        1e-14 is about 1e-11 px for a 1000 px focal length).

    Returns
    -------
    (N, 2) float64 undistorted normalised coordinates; NaN rows where Newton did not converge (far outside
    the region where the distortion polynomial is invertible).
    """
    from rangekit._compiled import lens as LK

    d = _full_coeffs(np.asarray(dist, dtype=np.float64))
    target = np.ascontiguousarray(xy_distorted, dtype=np.float64)
    xy = target.copy()
    if not np.any(d) or len(xy) == 0:
        return xy
    # Compiled passes (rangekit._compiled.lens), numpy's numbers: every point steps until the worst converges.
    nxt, res = np.empty_like(xy), np.empty(len(xy))
    for _ in range(max_iterations):
        LK.newton_pass(xy, target, d, nxt, res)
        if not res.max() >= tol:
            break
        xy, nxt = nxt, xy
    LK.newton_check(xy, target, d, 1e3 * tol)
    return xy
