"""Photometric stereo, normal integration and depth meshing against analytic truth (numpy-rendered)."""

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.photometric import (angular_error, depth_to_mesh, integrate_normals, photometric_stereo,
                                  uncalibrated_photometric_stereo)


def _sphere(H=96, W=96, radius_px=None):
    """Orthographic unit sphere: normals (H, W, 3) facing the camera (n_z < 0), NaN outside; mask."""
    R = radius_px or 0.45 * min(H, W)
    v, u = np.mgrid[0:H, 0:W].astype(float)
    x, y = (u - (W - 1) / 2) / R, (v - (H - 1) / 2) / R
    r2 = x * x + y * y
    mask = r2 < 0.95 ** 2
    n = np.dstack([x, y, -np.sqrt(np.clip(1 - r2, 0, None))])
    n[~mask] = np.nan
    return n, mask


def _lights(f, max_angle_deg=60.0, seed=0):
    """Unit lights on the camera's side (s_z < 0) within a cone about the optical axis."""
    rng = np.random.default_rng(seed)
    th = np.radians(max_angle_deg) * np.sqrt(rng.random(f))
    ph = 2 * np.pi * rng.random(f)
    return np.column_stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)])


def _render(n, mask, L, albedo=0.8, ks=0.0, shininess=40, cast=0.0, noise=0.0, seed=1):
    """Lambertian max(n.s, 0) (attached shadows) + Blinn-Phong highlight + random cast shadows + noise."""
    rng = np.random.default_rng(seed)
    nn = np.nan_to_num(n)
    d = np.einsum("hwi,fi->fhw", nn, L)
    I = albedo * np.maximum(d, 0)
    if ks:
        h = L + np.array([0.0, 0.0, -1.0])  # half vector between light and view (towards camera = -z)
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        I += ks * np.maximum(np.einsum("hwi,fi->fhw", nn, h), 0) ** shininess * (d > 0)
    if cast:
        I[rng.random(I.shape) < cast] = 0.0
    if noise:
        I += noise * rng.standard_normal(I.shape)
    I[:, ~mask] = 0.0
    return I.astype(np.float32)


def test_least_squares_noiseless_lambertian_is_exact():
    n, mask = _sphere()
    L = _lights(12, max_angle_deg=30)
    lit = (np.einsum("hwi,fi->fhw", np.nan_to_num(n), L) > 0).all(0) & mask  # no shadows: LS exact
    res = photometric_stereo(_render(n, lit, L), L, lit)
    err = angular_error(res.normals, n, lit)
    assert err.mean_deg <= 0.05, err[:2]
    assert np.nanmax(np.abs(res.albedo[lit] - 0.8)) < 1e-4
    assert np.all(np.isnan(res.normals[~lit]))
    assert np.nanmax(res.normals[..., 2]) < 0  # facing the camera


def test_rgb_per_channel_and_grey():
    n, mask = _sphere(48, 48)
    L = _lights(10, max_angle_deg=25)
    lit = (np.einsum("hwi,fi->fhw", np.nan_to_num(n), L) > 0).all(0) & mask
    grey = _render(n, lit, L, albedo=1.0)
    rgb = grey[..., None] * np.array([0.2, 0.5, 0.9], dtype=np.float32)
    per = photometric_stereo(rgb, L, lit, channels="per-channel")
    assert per.albedo.shape == (48, 48, 3)
    assert np.allclose(per.albedo[lit], [0.2, 0.5, 0.9], atol=1e-4)
    assert angular_error(per.normals, n, lit).mean_deg < 0.05
    g = photometric_stereo(rgb, L, lit)
    assert np.allclose(g.albedo[lit], (0.2 + 0.5 + 0.9) / 3, atol=1e-4)


def test_robust_beats_least_squares_with_shadows_and_highlights():
    n, mask = _sphere(128, 128)
    L = _lights(48, max_angle_deg=60)
    I = _render(n, mask, L, ks=0.6, cast=0.05, noise=0.003)
    ls = angular_error(photometric_stereo(I, L, mask, method="ls").normals, n, mask)
    rb = angular_error(photometric_stereo(I, L, mask, method="robust").normals, n, mask)
    assert ls.mean_deg > 4.0, ls[:2]           # the corruption really hurts plain least squares
    assert rb.mean_deg <= ls.mean_deg / 3, (ls[:2], rb[:2])
    assert rb.mean_deg < 1.0, rb[:2]


def test_uncalibrated_sphere_resolves_gbr_and_convexity():
    n, mask = _sphere(96, 96)
    L = _lights(16, max_angle_deg=50, seed=3)
    res = uncalibrated_photometric_stereo(_render(n, mask, L), mask)
    err = angular_error(res.normals, n, mask)
    assert err.mean_deg <= 2.0, err[:2]
    est = res.lights / np.linalg.norm(res.lights, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(np.sum(est * L, axis=1), -1, 1))).max() < 2.0


def _bump(H, W, pixel_size):
    """Smooth non-periodic surface Z(u, v) in metres and its exact normals (facing the camera)."""
    v, u = np.mgrid[0:H, 0:W].astype(float)
    x, y = u * pixel_size, v * pixel_size
    sx, sy = W * pixel_size, H * pixel_size
    Z = 0.5 + 0.03 * np.exp(-(((x - 0.5 * sx) / (0.25 * sx)) ** 2 + ((y - 0.4 * sy) / (0.3 * sy)) ** 2)) \
        + 0.01 * x / sx - 0.02 * np.sin(2.0 * y / sy)
    # exact derivatives
    gx = (-2 * (x - 0.5 * sx) / (0.25 * sx) ** 2) * (Z - 0.5 - 0.01 * x / sx + 0.02 * np.sin(2.0 * y / sy)) \
        + 0.01 / sx
    gy = (-2 * (y - 0.4 * sy) / (0.3 * sy) ** 2) * (Z - 0.5 - 0.01 * x / sx + 0.02 * np.sin(2.0 * y / sy)) \
        - 0.04 / sy * np.cos(2.0 * y / sy)
    n = np.dstack([gx, gy, -np.ones_like(Z)])
    return Z, n / np.linalg.norm(n, axis=2, keepdims=True)


def _rms_rel(Z, Z_true, mask):
    d = (Z - Z_true)[mask]
    d = d - d.mean()
    return np.sqrt(np.mean(d ** 2)) / np.ptp(Z_true[mask])


def test_lsq_integration_on_l_shaped_mask():
    H, W, ps = 120, 100, 1e-3
    Z_true, n = _bump(H, W, ps)
    mask = np.ones((H, W), bool)
    mask[:60, 50:] = False  # L shape
    Z = integrate_normals(n, mask, pixel_size=ps, median_depth=float(np.median(Z_true[mask])))
    assert np.all(np.isnan(Z[~mask])) and np.all(np.isfinite(Z[mask]))
    assert _rms_rel(Z, Z_true, mask) <= 0.005
    assert abs(np.median(Z[mask]) - np.median(Z_true[mask])) < 1e-12


def test_lsq_integration_full_size():
    """The DiLiGenT size; its speed is measured by benchmarks/photometric/bench_photometric.py, not here."""
    H, W, ps = 512, 612, 1e-4
    Z_true, n = _bump(H, W, ps)
    Z = integrate_normals(n, pixel_size=ps)
    assert _rms_rel(Z, Z_true, np.ones((H, W), bool)) <= 0.005


def test_fft_integration_on_rectangle():
    H, W, ps = 100, 140, 1e-3
    Z_true, n = _bump(H, W, ps)
    Z = integrate_normals(n, pixel_size=ps, method="fft")
    assert _rms_rel(Z, Z_true, np.ones((H, W), bool)) <= 0.01
    with pytest.raises(InputError, match="rectangle"):
        integrate_normals(n, np.pad(np.ones((H - 2, W), bool), ((1, 1), (0, 0))), method="fft")


def test_perspective_integration_of_sphere_and_mesh():
    K = np.array([[300.0, 0, 80], [0, 300.0, 60], [0, 0, 1]])
    H, W = 120, 160
    centre, radius = np.array([0.0, 0.0, 1.0]), 0.25
    v, u = np.mgrid[0:H, 0:W].astype(float)
    rays = np.dstack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)])
    d = rays / np.linalg.norm(rays, axis=2, keepdims=True)
    b = d @ centre
    disc = b * b - (centre @ centre - radius ** 2)
    mask = disc > 0.2 * radius ** 2  # stay off the limb
    t = b - np.sqrt(np.where(mask, disc, 0))
    P = d * t[..., None]
    n = (P - centre) / radius
    n[~mask] = np.nan
    Z_true = np.where(mask, P[..., 2], np.nan)
    Z = integrate_normals(n, mask, camera=K, median_depth=float(np.nanmedian(Z_true)))
    assert np.sqrt(np.nanmean((Z - Z_true) ** 2)) <= 0.005 * np.nanmax(Z_true - np.nanmin(Z_true))
    V, F = depth_to_mesh(Z, mask, camera=K)
    assert len(V) == mask.sum()
    assert np.allclose(V, P[mask], atol=5e-3 * radius)
    # faces wind towards the camera: their normals agree with the sphere's outward normals
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    centroid = V[F].mean(axis=1)
    assert np.mean(np.sum(fn * (centroid - centre), axis=1) > 0) > 0.99


def test_depth_to_mesh_orthographic_counts():
    Z = np.zeros((3, 4))
    Z[0, 0] = np.nan  # one quad loses a corner -> one triangle there
    V, F = depth_to_mesh(Z, pixel_size=0.01)
    assert V.shape == (11, 3) and np.isclose(V[:, 0].max(), 0.03)
    assert len(F) == 2 * 6 - 1
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    assert np.all(fn[:, 2] < 0)


@pytest.mark.parametrize("case, match", [
    ("two_images", "at least 3"),
    ("lights_shape", r"expected shape \(4, 3\)"),
    ("not_unit", r"rows \[2\] are not unit"),
    ("sizes", "same size"),
    ("empty_mask", "no pixel"),
    ("nan", "NaN"),
    ("method", "'ls' or 'robust'"),
])
def test_bad_input_errors(case, match):
    rng = np.random.default_rng(0)
    images = rng.random((4, 8, 8))
    L = _lights(4)
    mask = None
    if case == "two_images":
        images, L = images[:2], L[:2]
    elif case == "lights_shape":
        L = L[:3]
    elif case == "not_unit":
        L = L.copy()
        L[2] *= 1.1
    elif case == "sizes":
        images = [images[0], images[1], images[2][:7]]
        L = L[:3]
    elif case == "empty_mask":
        mask = np.zeros((8, 8), bool)
    elif case == "nan":
        images[1, 3, 3] = np.nan
    with pytest.raises(InputError, match=match):
        photometric_stereo(images, L, mask, method="bogus" if case == "method" else "ls")
