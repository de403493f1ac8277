"""Per-point uncertainty of coded light: the along-ray Jacobian of ray-plane and ray-ray
triangulation against finite differences, the predicted sigma on a plane against a Monte-Carlo of the
decoder's noise, and the sigma field through PointCloud, merge and the PLY round trip."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from rangekit.camera import pixel_rays
from rangekit.coded.decode import decode
from rangekit.coded.patterns import make_pattern_spec
from rangekit.coded.triangulate import triangulate_ray_plane, triangulate_ray_ray
from rangekit.coded.uncertainty import NoiseModel, along_ray_jacobian, fit_noise_model, point_sigma
from rangekit.errors import InputError
from rangekit.formats.clouds import load_cloud, save_cloud
from rangekit.geometry import transform_vectors
from rangekit.sim import default_rig
from rangekit.surface.cloud import PointCloud, merge_clouds, transform_cloud


def _plane_view(W=64, H=48, dist=None):
    """Camera (W x H), projector (optionally with ``dist``), the true projector (col, row) of a plane through
    the turntable's centre, tilted from facing the camera (NaN outside the projector), and the unit camera
    rays (H, W, 3)."""
    r = default_rig()
    cam = r.camera.resized(W, H)
    proj = r.projector if dist is None else replace(r.projector, dist=np.asarray(dist, float))
    d = transform_vectors(cam.T_world_cam, pixel_rays(cam).reshape(-1, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = r.T_world_table[:3, 3] + 0.04 * r.T_world_table[:3, 2]
    n = cam.center - centre
    n = n / np.linalg.norm(n) + np.array([0.15, -0.1, 0.05])
    n /= np.linalg.norm(n)
    t = -(n @ cam.center - n @ centre) / (d @ n)
    uv = proj.project(cam.center + t[:, None] * d)
    inside = (uv[:, 0] > 1) & (uv[:, 0] < proj.width - 2) & (uv[:, 1] > 1) & (uv[:, 1] < proj.height - 2) & (t > 0)
    uv[~inside] = np.nan
    return cam, proj, uv[:, 0].reshape(H, W), uv[:, 1].reshape(H, W), d.reshape(H, W, 3)


def _along(xyz_plus, xyz_minus, rays, h):
    return np.sum((xyz_plus - xyz_minus) * rays, axis=2) / (2 * h)


@pytest.mark.parametrize("dist", [None, [0.05, -0.02, 0.001, 0.0005, 0.0]])
def test_jacobian_matches_finite_differences(dist):
    cam, proj, col, row, rays = _plane_view(dist=dist)
    h = 1e-3
    g, none = along_ray_jacobian(cam, proj, triangulate_ray_plane(cam, proj, col).xyz)
    fd = _along(triangulate_ray_plane(cam, proj, col + h).xyz, triangulate_ray_plane(cam, proj, col - h).xyz, rays, h)
    assert none is None and np.array_equal(np.isfinite(g), np.isfinite(col)) and np.isfinite(col).mean() > 0.8
    assert np.nanmax(np.abs(g / fd - 1)) < 1e-5
    assert 0.5e-3 < np.nanmedian(np.abs(g)) < 2e-3                  # about 1 mm per projector column here
    gc, gr = along_ray_jacobian(cam, proj, triangulate_ray_ray(cam, proj, col, row).xyz, row, col)
    for gk, (dc, dr) in ((gc, (h, 0)), (gr, (0, h))):
        fd = _along(triangulate_ray_ray(cam, proj, col + dc, row + dr).xyz,
                    triangulate_ray_ray(cam, proj, col - dc, row - dr).xyz, rays, h)
        assert np.nanmax(np.abs(gk - fd)) < 1e-5 * np.nanmax(np.abs(gk))
    # sigma combines both: sqrt((gc sc)^2 + (gr sr)^2)
    s = point_sigma(cam, proj, triangulate_ray_ray(cam, proj, col, row).xyz, np.full(col.shape, 0.1),
                    np.full(col.shape, 0.2), col, row)
    np.testing.assert_allclose(s, np.hypot(0.1 * gc, 0.2 * gr), rtol=1e-6, equal_nan=True)


def test_jacobian_refuses_a_map_of_the_wrong_size():
    cam, proj, col, _, _ = _plane_view()
    with pytest.raises(InputError, match=r"xyz has shape \(3, 3, 3\).*must be \(48, 64, 3\)"):
        along_ray_jacobian(cam, proj, np.zeros((3, 3, 3)))


def test_noise_model_fit_recovers_shot_and_read_noise():
    rng = np.random.default_rng(0)
    L = rng.uniform(100, 3000, 200_000)
    D = rng.standard_normal(L.size) * np.sqrt(4 * 9.0 + 2 * 0.7 * L)
    m = fit_noise_model(L, D ** 2, ka=4, kb=2)
    assert m.a == pytest.approx(9.0, rel=0.15) and m.b == pytest.approx(0.7, rel=0.02)
    assert fit_noise_model(L[:10], D[:10] ** 2).b == 0.0        # too few samples: a constant


@pytest.mark.parametrize("method", ["hybrid", "phase"])
def test_sigma_on_a_plane_matches_a_monte_carlo_of_decoder_noise(method):
    """A hybrid (noise measured on the Gray-code pairs) or phase (on the alternating sum) capture of a plane synthesised from the projected frames at the exact projector coordinates,
    12-bit, with shot + read noise of known size: the spread of the triangulated points over noise draws
    matches the predicted sigma, in the dark and in the bright half of the image."""
    cam, proj, col, row, rays = _plane_view(W=40, H=30)
    spec = make_pattern_spec(method, proj.size)
    inside = np.isfinite(col)
    rc = [np.nan_to_num(row).ravel(), np.nan_to_num(col).ravel()]
    frames = np.stack([map_coordinates(f.astype(np.float32), rc, order=1).reshape(col.shape) * inside
                       for f in spec.frames()]) / 255.0
    H, W = col.shape
    albedo = np.linspace(0.15, 0.9, W)[None, :] * np.ones((H, 1))   # dark on the left, bright on the right
    clean = 40.0 + 3000.0 * albedo * frames                        # DN, full scale 4095
    noise = NoiseModel(16.0, 0.5)
    rng = np.random.default_rng(1)
    xs, sig = [], []
    for _ in range(48):
        img = clean + noise.std(clean) * rng.standard_normal(clean.shape)
        dec = decode(np.clip(np.rint(img), 0, 4095).astype(np.uint16), spec, subpixel=False, full_scale=4095)
        xyz = triangulate_ray_ray(cam, proj, dec.proj_col, dec.proj_row).xyz
        xs.append(np.sum(xyz * rays, axis=2))
        sig.append(point_sigma(cam, proj, xyz, dec.col_std, dec.row_std, dec.proj_col, dec.proj_row))
    xs, sig = np.array(xs), np.array(sig)
    ok = np.all(np.isfinite(xs), axis=0)
    assert ok.sum() > 0.95 * inside.sum()
    observed = np.std(xs, axis=0, ddof=1)
    predicted = np.sqrt(np.mean(sig.astype(np.float64) ** 2, axis=0))
    for half in (slice(0, W // 2), slice(W // 2, W)):
        o, p = observed[:, half][ok[:, half]], predicted[:, half][ok[:, half]]
        ratio = np.sqrt(np.mean(o ** 2) / np.mean(p ** 2))
        assert ratio == pytest.approx(1.0, abs=0.05), ratio
    # the dark half is noisier, as predicted
    assert np.nanmedian(predicted[:, :5]) > 1.8 * np.nanmedian(predicted[:, -5:])


def test_sigma_field_survives_merge_transform_and_the_ply_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    c = PointCloud(rng.normal(size=(50, 3)), rng.uniform(size=(50, 3)), None, rng.uniform(1e-6, 1e-4, 50))
    assert c.sigma.dtype == np.float32 and "sigma" in repr(c)
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.3]
    m = merge_clouds([c, transform_cloud(c, T)], [np.eye(4), np.eye(4)])
    np.testing.assert_array_equal(m.sigma, np.concatenate([c.sigma, c.sigma]))
    assert merge_clouds([c, PointCloud(c.points)], [np.eye(4), np.eye(4)]).sigma is None
    np.testing.assert_array_equal(c.take(c.sigma > 5e-5).sigma, c.sigma[c.sigma > 5e-5])
    save_cloud(tmp_path / "c.ply", m)
    assert b"property float sigma" in (tmp_path / "c.ply").read_bytes()[:400]
    back = load_cloud(tmp_path / "c.ply")
    np.testing.assert_array_equal(back.sigma, m.sigma)
    np.testing.assert_array_equal(back.points, m.points)
    save_cloud(tmp_path / "plain.ply", PointCloud(c.points))
    assert load_cloud(tmp_path / "plain.ply").sigma is None
    with pytest.raises(InputError, match=r"sigma must be \(50,\), found \(3,\)"):
        PointCloud(c.points, sigma=np.zeros(3))


def test_quality_map_measures_the_disagreement_of_overlapping_views():
    """A flat mesh seen by three views at heights +d, 0 and -d (the third only over x < 0): the
    disagreement is d where all three see it, d / sqrt(2) where two do, NaN outside every view."""
    from rangekit.surface.quality import vertex_normals, view_disagreement

    g = np.linspace(-0.05, 0.05, 21)
    X, Y = np.meshgrid(g, g)
    V = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i = np.arange(20)[:, None] * 21 + np.arange(20)[None, :]
    F = np.concatenate([np.stack([i, i + 1, i + 22], -1).reshape(-1, 3), np.stack([i, i + 22, i + 21], -1).reshape(-1, 3)])
    n = vertex_normals(V, F)
    np.testing.assert_allclose(np.abs(n[:, 2]), 1.0)
    f = np.linspace(-0.06, 0.06, 241)
    FX, FY = np.meshgrid(f, f)
    P = np.column_stack([FX.ravel(), FY.ravel(), np.zeros(FX.size)])
    d = 2e-4
    views = [P + [0, 0, d], P, (P - [0, 0, d])[P[:, 0] < 0.0]]
    q = view_disagreement(V, n, views, radius=2e-3)
    left, right = V[:, 0] < -0.002, V[:, 0] > 0.002
    np.testing.assert_allclose(q.disagreement[left], d, rtol=1e-9)
    np.testing.assert_allclose(q.disagreement[right], d / np.sqrt(2), rtol=1e-9)
    assert np.all(q.n_views[left] == 3) and np.all(q.n_views[right] == 2)
    far = view_disagreement(V + [1.0, 0, 0], n, views, radius=2e-3)
    assert np.all(np.isnan(far.disagreement)) and np.all(far.n_views == 0)
    with pytest.raises(InputError, match="radius must be"):
        view_disagreement(V, n, views, radius=0.0)
