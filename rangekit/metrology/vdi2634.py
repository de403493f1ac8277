"""The figures of VDI/VDE 2634 part 2 (optical 3D measuring systems, area scanning), from measured points.

Every figure is a length in metres (the callers print millimetres):

- **PF, probing error form**: the range ``max e - min e`` of the radial residuals ``e`` of the Gaussian
  (least squares) sphere fitted to the points of one sphere measurement (:func:`probing`).
- **PS, probing error size**: the fitted sphere's diameter minus the calibrated diameter (signed).
- **SD, sphere-spacing error**: the distance between the fitted centres of a ball bar's two spheres minus
  the calibrated distance (signed; one value per ball bar position, :func:`sphere_spacing`).
- **F, flatness measurement error**: the range ``max d - min d`` of the signed distances ``d`` of the
  points of a plane measurement from their Gaussian plane (:func:`flatness`).

The guideline lets up to 0.3 % of a measurement's points go as outliers (:data:`MAX_OUTLIER_FRACTION`):
with ``outlier_fraction`` f, the ``floor(f N)`` points farthest from the first fit are dropped and the
figure is taken from a refit of the rest. f = 0 (the default) keeps every point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError
from rangekit.metrology.plane_fit import LsqPlane, fit_plane_lsq
from rangekit.metrology.sphere_fit import SphereFit, fit_sphere

__all__ = ["MAX_OUTLIER_FRACTION", "ProbingResult", "FlatnessResult", "probing", "sphere_spacing", "flatness",
           "kept_after_outliers"]

#: The largest share of a measurement's points the guideline allows to be dropped as outliers.
MAX_OUTLIER_FRACTION = 0.003


@dataclass(frozen=True, eq=False)
class ProbingResult:
    """One sphere measurement: ``fit`` over the kept points, ``PF`` and ``PS`` (metres, PS signed),
    ``n_points`` given and ``n_excluded`` dropped by the outlier rule."""

    fit: SphereFit
    PF: float
    PS: float
    n_points: int
    n_excluded: int


@dataclass(frozen=True, eq=False)
class FlatnessResult:
    """One plane measurement: ``fit`` over the kept points, ``F`` (metres), points given and excluded."""

    fit: LsqPlane
    F: float
    n_points: int
    n_excluded: int


def kept_after_outliers(residuals, fraction: float) -> np.ndarray:
    """(N,) bool: every point but the ``floor(fraction * N)`` of largest ``|residual|`` (ties: the first kept).

    Raises InputError for a fraction outside ``[0, MAX_OUTLIER_FRACTION]``.
    """
    f = float(fraction)
    if not 0.0 <= f <= MAX_OUTLIER_FRACTION:
        raise InputError(f"outlier_fraction: expected a share in [0, {MAX_OUTLIER_FRACTION}] (VDI/VDE 2634-2 allows "
                         f"at most 0.3 % of the points to be dropped), found {fraction!r}")
    e = np.abs(np.asarray(residuals, dtype=np.float64))
    n_drop = int(np.floor(f * len(e)))
    keep = np.ones(len(e), dtype=bool)
    if n_drop:
        keep[np.argsort(-e, kind="stable")[:n_drop]] = False
    return keep


def _fit_with_outlier_rule(fit_fn, P: np.ndarray, outlier_fraction: float, what: str):
    """``(fit, keep)``: ``fit_fn`` on all points, then again without the points the guideline's outlier rule
    drops (:func:`kept_after_outliers`), if any."""
    fit = fit_fn(P, what=what)
    keep = kept_after_outliers(fit.residuals, outlier_fraction)
    if not keep.all():
        fit = fit_fn(P[keep], what=what)
    return fit, keep


def probing(points, calibrated_diameter: float, *, outlier_fraction: float = 0.0,
            what: str = "sphere points") -> ProbingResult:
    """PF and PS of one sphere measurement ((N, 3) points, metres; the calibrated diameter in metres)."""
    d = float(calibrated_diameter)
    if not (np.isfinite(d) and d > 0):
        raise InputError(f"{what}: calibrated diameter must be a positive length in metres, found {calibrated_diameter!r}")
    P = np.asarray(points, dtype=np.float64)
    fit, keep = _fit_with_outlier_rule(fit_sphere, P, outlier_fraction, what)
    e = fit.residuals
    return ProbingResult(fit, float(e.max() - e.min()), 2.0 * fit.radius - d, len(P), int((~keep).sum()))


def sphere_spacing(centre_a, centre_b, calibrated_distance: float) -> float:
    """SD: ``|centre_a - centre_b| - calibrated_distance`` (metres, signed)."""
    L = float(calibrated_distance)
    if not (np.isfinite(L) and L > 0):
        raise InputError(f"ball bar: calibrated distance must be a positive length in metres, found "
                         f"{calibrated_distance!r}")
    return float(np.linalg.norm(np.asarray(centre_a, float) - np.asarray(centre_b, float)) - L)


def flatness(points, *, outlier_fraction: float = 0.0, what: str = "plane points") -> FlatnessResult:
    """F of one plane measurement ((N, 3) points, metres)."""
    P = np.asarray(points, dtype=np.float64)
    fit, keep = _fit_with_outlier_rule(fit_plane_lsq, P, outlier_fraction, what)
    r = fit.residuals
    return FlatnessResult(fit, float(r.max() - r.min()), len(P), int((~keep).sum()))
