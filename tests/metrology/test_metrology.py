"""rangekit.metrology: the sphere and plane fits and the VDI/VDE 2634-2 figures on exact synthetic points."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.metrology import (fit_plane_lsq, fit_sphere, flatness, kept_after_outliers, probing,
                                sphere_spacing)


def _cap(n: int, half_angle_deg: float, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) unit vectors uniformly over a cap of the given half angle about +z (a single view's sphere)."""
    cos_max = np.cos(np.radians(half_angle_deg))
    z = rng.uniform(cos_max, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def test_sphere_fit_exact_on_a_cap():
    rng = np.random.default_rng(1)
    c, r = np.array([0.031, -0.012, 0.087]), 0.02
    fit = fit_sphere(c + r * _cap(2000, 53.0, rng))
    assert np.allclose(fit.centre, c, atol=1e-12) and abs(fit.radius - r) < 1e-12
    assert np.max(np.abs(fit.residuals)) < 1e-12


def test_sphere_fit_is_least_squares_not_algebraic():
    """With noise the Gauss-Newton result has zero gradient of sum e^2 and beats the algebraic start."""
    rng = np.random.default_rng(2)
    c, r = np.array([0.0, 0.0, 0.1]), 0.02
    P = c + (r + rng.normal(0, 2e-5, 3000))[:, None] * _cap(3000, 50.0, rng)
    fit = fit_sphere(P)
    D = P - fit.centre
    u = D / np.linalg.norm(D, axis=1, keepdims=True)
    e = fit.residuals
    # Normal equations of the geometric fit: sum e u = 0 and sum e = 0.
    assert np.abs(u.T @ e).max() < 1e-12 and abs(e.sum()) < 1e-12
    assert np.linalg.norm(fit.centre - c) < 5e-6 and abs(fit.radius - r) < 5e-6


def test_probing_form_and_size_equal_a_known_perturbation():
    """A bump of +a at one point and a dent of -b at another, on a dense exact sphere: PF = a + b, PS = 0."""
    rng = np.random.default_rng(3)
    c, r = np.array([0.01, 0.02, 0.3]), 0.025
    u = _cap(20000, 55.0, rng)
    radii = np.full(len(u), r)
    radii[10], radii[20] = r + 7e-6, r - 3e-6
    res = probing(c + radii[:, None] * u, 2 * r)
    # (the two points move the fit by ~1e-9 m: 1/20000 of their 10 um, times their leverage on a cap)
    assert res.PF == pytest.approx(10e-6, abs=5e-9)
    assert abs(res.PS) < 5e-9
    # A sphere measured 20 um too large: PS = +40 um exactly, PF = 0.
    big = probing(c + (r + 20e-6) * u, 2 * r)
    assert big.PS == pytest.approx(40e-6, abs=1e-12) and big.PF < 1e-12


def test_outlier_rule_drops_at_most_0_3_percent():
    rng = np.random.default_rng(4)
    c, r = np.zeros(3), 0.02
    u = _cap(1000, 50.0, rng)
    radii = np.full(1000, r)
    radii[[5, 6, 7]] = r + 1e-3        # 3 outliers = 0.3 % of 1000
    P = c + radii[:, None] * u
    assert probing(P, 2 * r).PF > 9e-4
    res = probing(P, 2 * r, outlier_fraction=0.003)
    assert res.n_excluded == 3 and res.PF < 1e-12 and abs(res.PS) < 1e-12
    assert kept_after_outliers(np.arange(10.0), 0.003).all()      # floor(0.03) = 0 points dropped
    with pytest.raises(InputError, match="0.3 %"):
        probing(P, 2 * r, outlier_fraction=0.01)


def test_sphere_spacing_error():
    rng = np.random.default_rng(5)
    a, b = np.array([0.0, 0.0, 0.1]), np.array([0.09, 0.05, 0.12])
    L = float(np.linalg.norm(a - b))
    fa, fb = (fit_sphere(c + 0.02 * _cap(500, 50.0, rng)) for c in (a, b))
    assert abs(sphere_spacing(fa.centre, fb.centre, L)) < 1e-12
    # Centre b moved 30 um along the bar: SD = +30 um.
    d = (b - a) / L
    fb2 = fit_sphere(b + 30e-6 * d + 0.02 * _cap(500, 50.0, rng))
    assert sphere_spacing(fa.centre, fb2.centre, L) == pytest.approx(30e-6, abs=1e-11)
    with pytest.raises(InputError, match="calibrated distance"):
        sphere_spacing(a, b, -1.0)


def test_flatness_exact_and_with_a_step():
    rng = np.random.default_rng(6)
    n = np.array([0.2, -0.3, 1.0])
    n /= np.linalg.norm(n)
    e1 = np.cross(n, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    uv = rng.uniform(-0.08, 0.08, (5000, 2))
    P = np.array([0.0, 0.0, 0.05]) + uv[:, :1] * e1 + uv[:, 1:] * e2
    assert flatness(P).F < 1e-12
    assert np.allclose(np.abs(fit_plane_lsq(P).plane[:3] @ n), 1.0)
    # One point 12 um above and one 5 um below the plane: F = 17 um (the LSQ plane moves by < 1e-9 m).
    Q = P.copy()
    Q[0] += 12e-6 * n
    Q[1] -= 5e-6 * n
    assert flatness(Q).F == pytest.approx(17e-6, abs=2e-9)
    res = flatness(Q, outlier_fraction=0.0004)      # floor(0.0004 * 5000) = 2 points
    assert res.n_excluded == 2 and res.F < 1e-12


@pytest.mark.parametrize("bad, match", [
    (np.zeros((3, 3)), "at least 4"),
    (np.c_[np.random.default_rng(0).uniform(size=(50, 2)), np.zeros(50)], "fix no sphere"),
    (np.full((5, 3), np.nan), "finite"),
    (np.zeros((5, 2)), "shape"),
])
def test_sphere_fit_refuses_bad_points(bad, match):
    with pytest.raises(InputError, match=match):
        fit_sphere(bad)


def test_plane_fit_refuses_collinear_points():
    t = np.linspace(0, 1, 20)[:, None]
    with pytest.raises(InputError, match="collinear"):
        fit_plane_lsq(t * np.array([[1.0, 2.0, 3.0]]))
