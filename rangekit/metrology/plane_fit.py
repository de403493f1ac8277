"""Least-squares (Gaussian) plane fit, as VDI/VDE 2634 part 2 evaluates its flatness standard.

Total least squares over all the given points (the normal is the smallest right singular vector of the
centred points: :func:`rangekit.laser.plane_fit.tls_plane`, the one such fit). Unlike the laser's robust
fit (:func:`rangekit.laser.plane_fit.fit_plane`, which trims outliers), nothing is dropped here: the
guideline's figures are ranges over the evaluated points, and which points are excluded is its rule
(:mod:`rangekit.metrology.vdi2634`), not the fit's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError
from rangekit.laser.plane_fit import tls_plane
from rangekit.metrology.sphere_fit import check_points

__all__ = ["LsqPlane", "fit_plane_lsq"]


@dataclass(frozen=True, eq=False)
class LsqPlane:
    """plane : (4,) ``[n, d]`` with ``n . X + d = 0``, |n| = 1. residuals : (N,) signed distances (metres).
    rms : RMS distance (metres). spread : (3,) standard deviations along the principal axes, largest first."""

    plane: np.ndarray
    residuals: np.ndarray
    rms: float
    spread: np.ndarray


def fit_plane_lsq(points, *, what: str = "plane points") -> LsqPlane:
    """Gaussian least-squares plane through (N, 3) points.

    Raises
    ------
    InputError : not an (N, 3) finite array, fewer than 3 points, or (nearly) collinear points (the second
        principal spread below 1e-6 of the first).
    """
    P = check_points(points, what)
    if len(P) < 3:
        raise InputError(f"{what}: a plane needs at least 3 points, found {len(P)}")
    plane, spread, _ = tls_plane(P)
    if not spread[1] > 1e-6 * spread[0]:
        raise InputError(f"{what}: the {len(P)} points are (nearly) collinear (spread "
                         f"{np.round(spread * 1e3, 6).tolist()} mm); a plane needs points spread over an area")
    r = P @ plane[:3] + plane[3]
    return LsqPlane(plane=plane, residuals=r, rms=float(np.sqrt(np.mean(r * r))), spread=spread)
