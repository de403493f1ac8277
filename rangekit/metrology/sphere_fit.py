"""Least-squares (Gaussian) sphere fit to 3D points, as VDI/VDE 2634 part 2 evaluates its spheres.

Start: the algebraic fit, linear in ``(a, b, c, d)`` of ``|p|^2 = 2 p.c + d`` (centre ``c``, radius
``sqrt(d + |c|^2)``), exact for points on a sphere. Then Gauss-Newton on the geometric residuals
``e_i = |p_i - c| - r`` (Jacobian ``[-(p_i - c) / |p_i - c|, -1]``), which minimises ``sum e_i^2``: the
Gaussian (least squares) sphere the guideline prescribes. Iterates until the step is below 1e-13 m or
for at most 50 steps (on a cap of 100 degrees of a 40 mm sphere it takes 2-4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError

__all__ = ["SphereFit", "fit_sphere", "check_points"]

_MAX_STEPS = 50
_STEP_TOL = 1e-13   # metres


@dataclass(frozen=True, eq=False)
class SphereFit:
    """A fitted sphere.

    centre : (3,) metres, the points' frame. radius : metres.
    residuals : (N,) signed radial residuals ``|p - centre| - radius`` (metres), outward positive.
    rms : RMS of the residuals (metres). n_steps : Gauss-Newton steps taken.
    """

    centre: np.ndarray
    radius: float
    residuals: np.ndarray
    rms: float
    n_steps: int

    def __repr__(self) -> str:
        return (f"SphereFit(centre_mm={np.round(self.centre * 1e3, 4).tolist()}, radius_mm={self.radius * 1e3:.4f}, "
                f"rms_mm={self.rms * 1e3:.4f}, n={len(self.residuals)})")


def check_points(points, what: str) -> np.ndarray:
    """``points`` as a finite (N, 3) float64 array; InputError naming ``what`` otherwise."""
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"{what}: expected an (N, 3) array of points, found shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise InputError(f"{what}: expected finite points, found {int((~np.isfinite(P).all(axis=1)).sum())} "
                         "rows with NaN or inf")
    return P


def fit_sphere(points, *, what: str = "sphere points") -> SphereFit:
    """Gaussian least-squares sphere through (N, 3) points (module doc).

    Raises
    ------
    InputError : not an (N, 3) finite array, fewer than 4 points, or points that fix no sphere (coplanar
        or collinear: the algebraic system is rank deficient).
    """
    P = check_points(points, what)
    if len(P) < 4:
        raise InputError(f"{what}: a sphere needs at least 4 points, found {len(P)}")
    o = P.mean(axis=0)
    Q = P - o                                          # centred: better conditioned
    A = np.hstack([2.0 * Q, np.ones((len(Q), 1))])
    sv = np.linalg.svd(A, compute_uv=False)
    if not sv[-1] > 1e-9 * sv[0]:
        raise InputError(f"{what}: the {len(P)} points fix no sphere (coplanar or collinear: singular values "
                         f"{np.round(sv, 9).tolist()}); expected points spread over a cap of the sphere")
    sol, *_ = np.linalg.lstsq(A, np.einsum("ij,ij->i", Q, Q), rcond=None)
    c, r = sol[:3], float(np.sqrt(max(sol[3] + sol[:3] @ sol[:3], 0.0)))
    steps = 0
    for steps in range(1, _MAX_STEPS + 1):
        D = Q - c
        dist = np.linalg.norm(D, axis=1)
        e = dist - r
        J = np.hstack([-D / dist[:, None], -np.ones((len(Q), 1))])
        delta, *_ = np.linalg.lstsq(J, -e, rcond=None)
        c, r = c + delta[:3], r + float(delta[3])
        if np.linalg.norm(delta) < _STEP_TOL:
            break
    e = np.linalg.norm(Q - c, axis=1) - r
    return SphereFit(centre=c + o, radius=r, residuals=e, rms=float(np.sqrt(np.mean(e * e))), n_steps=steps)
