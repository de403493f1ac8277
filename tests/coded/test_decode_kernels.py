"""Issue 20, decode stage second pass: the compiled kernels give the numbers of the numpy code they replaced,
bit for bit, and the exact answers of analytic constructions.

Covered: the compiled undistortion (rangekit._compiled.lens) against the vectorised numpy Newton it
replaced; the ray-ray kernel (points, residuals, along-ray derivatives) against the numpy midpoint formula
and :func:`rangekit.coded.uncertainty.along_ray_jacobian`, and against points on a known plane; the phase
sums and the projector-response correction against :func:`rangekit.coded.phase.phase_from_steps` and
:class:`rangekit.coded.response.PhaseCorrection`; the read-ahead of :func:`rangekit.app.process.view_cache.view_clouds`.
"""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.camera import PinholeCamera
from rangekit.lens import _distort_jacobian, _full_coeffs, distort, undistort
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import make_pattern_spec
from rangekit.coded.phase import _noise_variance, _stack_phase, phase_from_steps
from rangekit.coded.response import phase_correction
from rangekit.coded.triangulate import triangulate_ray_ray
from rangekit.coded.uncertainty import along_ray_jacobian, point_sigma
from rangekit.geometry import look_at
from support.small_rigs import small_rig

DISTORTIONS = [
    [-0.02, 0.01, 0.0, 0.0, 0.0],
    [-0.08, 0.12, 2e-4, -1e-4, 0.0],
    [0.1, -0.3, 1e-3, 2e-3, 0.2, 0.01, 0.02, 0.03, 1e-3, 2e-3, 3e-3, 4e-3],
]


def _numpy_undistort(xy_distorted, dist, tol=1e-14, max_iterations=30):
    """The vectorised numpy Newton of rangekit.lens.undistort before the compiled kernels (the reference)."""
    d = _full_coeffs(np.asarray(dist, dtype=np.float64))
    target = np.asarray(xy_distorted, dtype=np.float64)
    xy = target.copy()
    if not np.any(d):
        return xy
    for _ in range(max_iterations):
        res = distort(xy, d) - target
        if not np.nanmax(np.abs(res), initial=0.0) >= tol:
            break
        J = _distort_jacobian(xy, d)
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy[:, 0] -= (J[:, 1, 1] * res[:, 0] - J[:, 0, 1] * res[:, 1]) / det
            xy[:, 1] -= (J[:, 0, 0] * res[:, 1] - J[:, 1, 0] * res[:, 0]) / det
    res = np.max(np.abs(distort(xy, d) - target), axis=1)
    xy[~(res < 1e3 * tol)] = np.nan
    return xy


@pytest.mark.parametrize("dist", DISTORTIONS)
def test_compiled_undistort_is_numpys_newton_bit_for_bit_and_inverts_distort(dist):
    rng = np.random.default_rng(len(dist))
    truth = rng.uniform(-0.5, 0.5, (20000, 2))
    xy_d = distort(truth, np.array(dist))
    xy_d[3] = np.nan          # an undecoded point stays NaN
    xy_d[5] = [40.0, -40.0]   # far out: converges or not (NaN) as numpy's did
    got = undistort(xy_d, np.array(dist))
    assert np.array_equal(got, _numpy_undistort(xy_d, np.array(dist)), equal_nan=True)
    assert np.isnan(got[3]).all()
    ok = np.isfinite(got[:, 0])
    ok[5] = False
    assert ok.sum() >= 19990
    assert np.max(np.abs(got[ok] - truth[ok])) < 1e-12          # the exact inverse (analytic truth)
    assert undistort(np.zeros((0, 2)), np.array(dist)).shape == (0, 2)


def _rig(W=96, H=72):
    cam = PinholeCamera(np.array([[120.0, 0, W / 2 - 0.3], [0, 121.0, H / 2 + 0.2], [0, 0, 1]]), W, H,
                        dist=np.array([-0.1, 0.05, 1e-3, -5e-4, 0.0]), T_world_cam=look_at([0.0, -0.5, 0.1], [0, 0, 0]))
    proj = PinholeCamera(np.array([[150.0, 0, 64.0], [0, 150.0, 40.0], [0, 0, 1]]), 128, 80,
                         dist=np.array(DISTORTIONS[2]), T_world_cam=look_at([0.2, -0.5, 0.1], [0, 0, 0]))
    return cam, proj


def _plane_codes(cam, proj, y0=0.05):
    """Exact projector (column, row) of each camera pixel on the plane y = y0, and the points (analytic)."""
    o, d = cam.rays(cam.pixel_grid())
    X = o + ((y0 - o[:, 1]) / d[:, 1])[:, None] * d
    uv = proj.project(X)
    inside = (uv[:, 0] > 0) & (uv[:, 0] < proj.width - 1) & (uv[:, 1] > 0) & (uv[:, 1] < proj.height - 1)
    uv[~inside] = np.nan
    H, W = cam.height, cam.width
    return uv[:, 0].reshape(H, W), uv[:, 1].reshape(H, W), X.reshape(H, W, 3)


def test_ray_ray_kernel_is_the_numpy_midpoint_bit_for_bit_and_on_the_true_plane():
    cam, proj = _rig()
    cols, rows, X = _plane_codes(cam, proj)
    tri = triangulate_ray_ray(cam, proj, cols, rows)
    valid = np.isfinite(cols) & np.isfinite(rows)
    assert valid.sum() > 2000
    # the numpy formula the kernel replaced (einsum dot products, BLAS rotation)
    o1, d1 = cam.rays(cam.pixel_grid())
    o1, d1 = o1[valid.ravel()], d1[valid.ravel()]
    xy = proj.pixels_to_normalized(np.column_stack([cols[valid], rows[valid]]))
    o2, d2 = proj.rays_from_normalized(xy)
    w0 = o1 - o2
    b, dd, e = (np.einsum("ij,ij->i", p, q) for p, q in ((d1, d2), (d1, w0), (d2, w0)))
    s, t = (b * e - dd) / (1 - b * b), (e - b * dd) / (1 - b * b)
    P1, P2 = o1 + s[:, None] * d1, o2 + t[:, None] * d2
    assert np.array_equal(tri.xyz[valid], 0.5 * (P1 + P2))
    assert np.array_equal(tri.residual[valid], np.linalg.norm(P1 - P2, axis=1))
    assert np.array_equal(tri.proj_xy[valid], xy)
    assert np.isnan(tri.xyz[~valid]).all() and np.isnan(tri.gains[~valid]).all()
    assert np.max(np.abs(tri.xyz[valid] - X[valid])) < 1e-9       # on the true plane to 1 nm
    assert np.nanmax(tri.residual) < 1e-9


def test_ray_ray_gains_are_the_along_ray_jacobian_and_give_the_same_sigma():
    cam, proj = _rig()
    cols, rows, _ = _plane_codes(cam, proj)
    tri = triangulate_ray_ray(cam, proj, cols, rows)
    g_col, g_row = along_ray_jacobian(cam, proj, tri.xyz, rows, cols)
    ok = np.isfinite(g_col)
    assert ok.sum() > 2000 and np.array_equal(ok, np.isfinite(tri.gains[:, :, 0]))
    for got, want in ((tri.gains[:, :, 0][ok], g_col[ok]), (tri.gains[:, :, 1][ok], g_row[ok])):
        assert np.max(np.abs(got - want)) < 1e-10 * np.max(np.abs(want))  # closed-form 2x2 inverse vs LAPACK
    std = np.full(cols.shape, 0.05, np.float32)
    fast = point_sigma(cam, proj, tri.xyz, std, std, cols, rows, gains=tri.gains)
    plain = point_sigma(cam, proj, tri.xyz, std, std, cols, rows)
    assert np.allclose(fast, plain, rtol=1e-6, equal_nan=True) and np.array_equal(np.isnan(fast), np.isnan(plain))
    with pytest.raises(Exception, match="gains"):
        point_sigma(cam, proj, tri.xyz, std, std, cols, rows, gains=tri.gains[:10])


def test_phase_correction_kernel_is_phasecorrection_bit_for_bit():
    from rangekit.coded import _kernels as K

    corr = phase_correction(2.2, 8)
    phi = np.random.default_rng(0).uniform(0, 2 * np.pi, 200000).astype(np.float32)
    edges = np.float32([0.0, -0.0, 1e-8, np.float32(2 * np.pi), np.nextafter(np.float32(2 * np.pi), 0), -1.0, 7.0, 100])
    phi = np.concatenate([phi, edges]).reshape(2, -1)
    out, slope = np.empty_like(phi), np.empty_like(phi)
    K.phase_correct(phi, corr.offset, out, slope)
    assert np.array_equal(out, corr(phi)) and np.array_equal(slope, corr.slope(phi))


@pytest.mark.parametrize("steps", [8, 5])
def test_stack_phase_is_phase_from_steps_bit_for_bit(steps):
    spec = make_pattern_spec("hybrid", (64, 32), axes=("columns",), steps=steps, period=16)
    rng = np.random.default_rng(steps)
    H, W = 40, 50
    phase = rng.uniform(0, 2 * np.pi, (H, W))
    frames = {n: rng.integers(0, 255, (H, W), dtype=np.uint8) for n in spec.frame_names}
    for s in range(steps):  # fringes with the true phase, plus noise (analytic construction)
        frames[f"col_p16_s{s}"] = np.clip(120 + 90 * np.cos(phase - 2 * np.pi * s / steps)
                                          + rng.normal(0, 2, (H, W)), 0, 255).astype(np.uint8)
    fr = CaptureStack([frames[n] for n in spec.frame_names], spec, "rangekit")
    names = [f"col_p16_s{s}" for s in range(steps)]
    region = (slice(7, 31), slice(None))
    phi, B, A, alt = _stack_phase(fr, [fr.index[n] for n in names], region)
    ref = phase_from_steps([frames[n][region] for n in names])
    for got, want in zip((phi, B, A), ref):
        assert np.array_equal(got, want)
    if steps % 2 == 0:
        want = _noise_variance([frames[n][region] for n in names], ref[2], ref[1], ref[0])
        assert np.array_equal(alt * alt / np.float32(steps), want)
    err = np.angle(np.exp(1j * (phi - phase[region])))
    assert np.percentile(np.abs(err), 95) < 0.1                   # the true phase, to the noise


def test_view_clouds_reads_ahead_and_gives_view_clouds_results_in_order(tmp_path):
    """The read-ahead pipeline yields, view by view, what view_cloud gives alone (fresh and from the cache),
    and a view whose frames cannot be read fails at its turn, after the views before it."""
    import shutil

    from rangekit.app.acquire.acquire import acquire
    from rangekit.app.process.view_cache import view_cloud, view_clouds
    from rangekit.errors import RangekitError
    from rangekit.formats.sessions.session import ScanPlan, Session
    from rangekit.geometry import invert_T
    from rangekit.sim import SimRig, default_scene

    rig = small_rig()
    s = SimRig(default_scene("lumpy"), rig, seed=2)
    spec = make_pattern_spec("hybrid", s.projector.resolution, steps=4, period=16)
    acquire(s, rig, spec, tmp_path / "a", plan=ScanPlan(n_views=3))
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    settings = {"method": "auto", "table_margin": 0.002}
    T_tw = invert_T(rig.T_world_table)

    def run(folder, pipelined):
        sess = Session.load(folder)
        views, args = sess.done_views, (sess.pattern, sess.rig, settings, sess.capture.full_scale, T_tw, 0.002)
        return list(view_clouds(views, *args)) if pipelined else [view_cloud(v, *args) for v in views]

    for cached in (False, True):
        piped, alone = run(tmp_path / "a", True), run(tmp_path / "b", False)
        assert len(piped) == 3 and all(len(c) > 500 for c, _ in piped)
        for (c1, m1), (c2, m2) in zip(piped, alone):
            assert np.array_equal(c1.points, c2.points) and np.array_equal(c1.sigma, c2.sigma)
            assert np.array_equal(m1.depth, m2.depth, equal_nan=True) and np.array_equal(m1.capture, m2.capture)
        assert all((v / "cloud.json").exists() for v in sorted((tmp_path / "a").glob("view_*")))
    sess = Session.load(tmp_path / "b")
    for v in sess.done_views:
        (v.folder / "cloud.json").unlink()
    (sess.done_views[2].folder / "007.png").write_bytes(b"not a png")
    it = view_clouds(sess.done_views, sess.pattern, sess.rig, settings, sess.capture.full_scale, T_tw, 0.002)
    assert len(next(it)[0]) > 500 and len(next(it)[0]) > 500      # views 0 and 1 come first
    with pytest.raises(RangekitError, match="007.png"):
        next(it)


def _numpy_smooth_along(coord, axis, half, max_step):
    """The numpy rule of smooth_along_stripes before its compiled kernel (the reference)."""
    import math

    taps = np.array([math.comb(2 * half, k) for k in range(2 * half + 1)], np.float64)
    taps /= taps.sum()
    along = 0 if axis == "columns" else 1
    pad = [(half, half) if a == along else (0, 0) for a in range(2)]
    padded = np.pad(coord.astype(np.float64), pad, constant_values=np.nan)
    n = coord.shape[along]
    centre = coord.astype(np.float64)
    acc = np.zeros_like(centre)
    with np.errstate(invalid="ignore"):
        for k, w in enumerate(taps):
            tap = np.take(padded, np.arange(k, k + n), axis=along)
            far = np.abs(tap - centre) > max_step * abs(k - half)
            acc += w * np.where(far, np.nan, tap)
    return np.where(np.isfinite(acc), acc, coord).astype(np.float32)


@pytest.mark.parametrize("axis", ["columns", "rows"])
def test_compiled_stripe_smoothing_is_the_numpy_rule_bit_for_bit(axis):
    from rangekit.coded.binary import smooth_along_stripes

    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:301, 0:257]
    coord = (0.37 * y + 1.7 * x + rng.normal(0, 0.3, y.shape)).astype(np.float32)
    coord[rng.random(coord.shape) < 0.05] = np.nan          # undecoded pixels
    coord[150:] += 40                                         # depth edges across and along
    coord[:, 100:] -= 7
    for half in (1, 2, 3, 4):
        for max_step in (2.0, 0.5):
            np.testing.assert_array_equal(smooth_along_stripes(coord, axis, half, max_step),
                                          _numpy_smooth_along(coord, axis, half, max_step))
