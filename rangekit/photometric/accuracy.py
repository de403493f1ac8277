"""How far estimated normals are from the truth: the angle between two normal maps."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rangekit.errors import InputError

__all__ = ["AngularError", "angular_error"]


class AngularError(NamedTuple):
    """Angle between estimated and true normals (a human-facing metric, hence degrees)."""

    mean_deg: float           # mean over the compared pixels; lower is better
    median_deg: float         # median over the compared pixels; lower is better
    per_pixel_deg: np.ndarray  # (H, W) float64, NaN where not compared


def angular_error(normals, normals_true, mask=None) -> AngularError:
    """Angle between two (H, W, 3) normal maps over ``mask`` (default: where both are finite)."""
    n = np.asarray(normals, dtype=np.float64)
    t = np.asarray(normals_true, dtype=np.float64)
    if n.shape != t.shape or n.ndim != 3 or n.shape[2] != 3:
        raise InputError(f"normals: expected two (H, W, 3) maps of the same shape, found {n.shape} and {t.shape}")
    m = np.isfinite(n).all(2) & np.isfinite(t).all(2)
    if mask is not None:
        m &= np.asarray(mask, dtype=bool)
    if not m.any():
        raise InputError("angular_error: no pixel where both normal maps are finite inside the mask")
    a = n[m] / np.linalg.norm(n[m], axis=1, keepdims=True)
    b = t[m] / np.linalg.norm(t[m], axis=1, keepdims=True)
    # atan2(|a x b|, a . b) is accurate for tiny angles (arccos is not).
    ang = np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1)))
    out = np.full(m.shape, np.nan)
    out[m] = ang
    return AngularError(float(ang.mean()), float(np.median(ang)), out)
