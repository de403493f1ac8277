"""The names of ``rangekit.metrology``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .sphere_fit import SphereFit as SphereFit, fit_sphere as fit_sphere
from .plane_fit import LsqPlane as LsqPlane, fit_plane_lsq as fit_plane_lsq
from .vdi2634 import (MAX_OUTLIER_FRACTION as MAX_OUTLIER_FRACTION, ProbingResult as ProbingResult,
    FlatnessResult as FlatnessResult, probing as probing, sphere_spacing as sphere_spacing, flatness as flatness,
    kept_after_outliers as kept_after_outliers)
