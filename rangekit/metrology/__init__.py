"""Metrology: least-squares fits of geometric standards and the VDI/VDE 2634 part 2 figures.

Modules: ``sphere_fit`` (Gaussian sphere fit, Gauss-Newton from an algebraic start), ``plane_fit``
(Gaussian plane fit), ``vdi2634`` (probing errors PF and PS, sphere-spacing error SD, flatness F).
"""

from rangekit.metrology.plane_fit import LsqPlane, fit_plane_lsq
from rangekit.metrology.sphere_fit import SphereFit, fit_sphere
from rangekit.metrology.vdi2634 import (MAX_OUTLIER_FRACTION, FlatnessResult, ProbingResult, flatness,
                                        kept_after_outliers, probing, sphere_spacing)

__all__ = ["SphereFit", "fit_sphere", "LsqPlane", "fit_plane_lsq", "MAX_OUTLIER_FRACTION", "ProbingResult",
           "FlatnessResult", "probing", "sphere_spacing", "flatness", "kept_after_outliers"]
