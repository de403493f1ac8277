"""A hole in a sphere closed by continuing the curvature around it (rangekit.surface.watertight.continue_curvature)
against the analytic sphere: the thin-plate fill continues only the slope and sags out of a wide cap; the
curvature's continuation brings the cap back onto the sphere."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from rangekit.errors import InputError
from rangekit.surface.watertight import _fair, continue_curvature

R = 0.05   # metres


def _sphere_with_cap(cap_deg: float):
    m = trimesh.creation.icosphere(subdivisions=5, radius=R)
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    free = V[:, 2] < -R * np.cos(np.radians(cap_deg))      # the cap around the bottom pole
    return V, F, free


def _radial_error(V: np.ndarray, free: np.ndarray) -> np.ndarray:
    return np.abs(np.linalg.norm(V[free], axis=1) - R)


def test_a_wide_cap_comes_back_onto_the_sphere():
    V, F, free = _sphere_with_cap(50.0)
    guess = _fair(V[F], F, free, V)                          # the thin-plate fill of the same hole, on its metric
    sag = _radial_error(guess, free)
    assert sag.max() > 0.03 * R                              # 1.9 mm out of 50: the slope alone sags
    out = continue_curvature(guess, F, free, max_curvature=1e3)
    err = _radial_error(out, free)
    assert err.max() < 0.2 * sag.max() and err.max() < 0.005 * R, (sag.max(), err.max())   # 0.18 mm
    assert np.array_equal(out[~free], guess[~free])          # the fixed vertices never move


def test_the_curvature_is_clipped():
    V, F, free = _sphere_with_cap(50.0)
    guess = _fair(V[F], F, free, V)
    # a clip below the sphere's own curvature (1 / R) continues a flatter surface: the cap stays nearer the fill
    flat = continue_curvature(guess, F, free, max_curvature=0.2 / R)
    assert _radial_error(flat, free).max() > 2 * _radial_error(continue_curvature(guess, F, free, max_curvature=1e3),
                                                                free).max()


def test_nothing_free_or_wrong_shapes():
    V, F, free = _sphere_with_cap(50.0)
    assert np.array_equal(continue_curvature(V, F, np.zeros(len(V), bool), max_curvature=1.0), V)
    with pytest.raises(InputError, match="free"):
        continue_curvature(V, F, free[:-1], max_curvature=1.0)
