"""Issue 20, the decode stage: every shortcut gives the numbers of the plain computation, bit for bit.

The per-rig caches (camera world rays, projector column planes), the projector coordinates shared by the
ray-ray triangulation and its sigma, the compiled filter + normals pass, the .npz levels, and the light
start-up of ``rangekit decode`` (no scipy.spatial, Open3D, simulator or app layer).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.coded.patterns import make_pattern_spec
from rangekit.coded.triangulate import (discontinuity_mask, filter_range_map, range_normals, triangulate_ray_plane,
                                        triangulate_ray_ray)
from rangekit.coded.uncertainty import point_sigma
from rangekit.geometry import look_at, transform_vectors
from rangekit.io import atomic_save_npz, write_png

ROOT = Path(__file__).resolve().parents[2]


def _rig(size=(96, 72)):
    """A small camera and projector 0.2 m apart looking at the origin, both with lens distortion."""
    W, H = size
    cam = PinholeCamera(np.array([[120.0, 0, W / 2 - 0.3], [0, 121.0, H / 2 + 0.2], [0, 0, 1]]), W, H,
                        dist=np.array([-0.1, 0.05, 1e-3, -5e-4, 0.0]), T_world_cam=look_at([0.0, -0.5, 0.1], [0, 0, 0]))
    proj = PinholeCamera(np.array([[150.0, 0, 64.0], [0, 150.0, 40.0], [0, 0, 1]]), 128, 80,
                         dist=np.array([-0.02, 0.01, 0.0, 0.0, 0.0]), T_world_cam=look_at([0.2, -0.5, 0.1], [0, 0, 0]))
    return cam, proj


def _plane_codes(cam: PinholeCamera, proj: PinholeCamera):
    """Exact projector (column, row) of every camera pixel on the plane y = 0.05 (analytic truth), and the points."""
    o, d = cam.rays(cam.pixel_grid())
    t = (0.05 - o[:, 1]) / d[:, 1]
    X = o + t[:, None] * d
    uv = proj.project(X)
    H, W = cam.height, cam.width
    return uv[:, 0].reshape(H, W), uv[:, 1].reshape(H, W), X.reshape(H, W, 3)


def test_world_rays_are_cached_per_pose_and_equal_the_plain_rays():
    cam, _ = _rig()
    o, d = world_pixel_rays(cam)
    o2, d2 = cam.rays(cam.pixel_grid())
    assert np.array_equal(d, d2) and np.array_equal(o, o2)
    assert world_pixel_rays(cam)[1] is d and not d.flags.writeable
    # rows of the cached rays are the rows rotated alone (what triangulation takes)
    from rangekit.camera import pixel_rays
    rows = np.random.default_rng(0).random(cam.width * cam.height) < 0.3
    assert np.array_equal(d[rows], transform_vectors(cam.T_world_cam, pixel_rays(cam).reshape(-1, 3)[rows]))
    moved = cam.with_pose(look_at([0.0, -0.4, 0.2], [0, 0, 0]))
    assert not np.array_equal(world_pixel_rays(moved)[1], d)  # another pose, other rays


def test_ray_plane_with_the_cached_plane_table_is_exact_and_repeatable():
    cam, proj = _rig()
    cols, _, X = _plane_codes(cam, proj)
    cols = np.where((cols > 0) & (cols < proj.width - 1), cols, np.nan)
    a = triangulate_ray_plane(cam, proj, cols)
    b = triangulate_ray_plane(cam, proj, cols)
    ok = np.isfinite(cols)
    assert ok.sum() > 1000
    assert np.array_equal(a.xyz, b.xyz, equal_nan=True)
    assert np.max(np.abs(a.xyz[ok] - X[ok])) < 1e-9  # on the true plane to 1 nm


def test_ray_ray_shares_projector_coordinates_with_sigma_bit_for_bit():
    cam, proj = _rig()
    cols, rows, X = _plane_codes(cam, proj)
    inside = (cols > 0) & (cols < proj.width - 1) & (rows > 0) & (rows < proj.height - 1)
    cols, rows = np.where(inside, cols, np.nan), np.where(inside, rows, np.nan)
    tri = triangulate_ray_ray(cam, proj, cols, rows)
    ok = tri.valid
    assert ok.sum() > 1000 and np.max(np.abs(tri.xyz[ok] - X[ok])) < 1e-9
    assert np.array_equal(np.isfinite(tri.proj_xy[:, :, 0]), inside)
    std = np.full(cols.shape, 0.05, np.float32)
    plain = point_sigma(cam, proj, tri.xyz, std, std, cols, rows)
    shared = point_sigma(cam, proj, tri.xyz, std, std, cols, rows, proj_xy=tri.proj_xy)
    assert np.array_equal(plain, shared, equal_nan=True) and np.isfinite(shared[ok]).all()


def _numpy_filter(xyz, vp, max_jump, margin, extra):
    drop = discontinuity_mask(xyz, vp, max_jump=max_jump, margin=margin)
    if extra is not None:
        drop |= extra
    out = xyz.copy()
    out[drop] = np.nan
    return out, range_normals(out, vp)


@pytest.mark.parametrize("margin", [0, 1, 2])
@pytest.mark.parametrize("with_extra", [False, True])
def test_compiled_filter_and_normals_equal_numpy_bit_for_bit(margin, with_extra):
    rng = np.random.default_rng(margin)
    H, W = 60, 80
    v, u = np.mgrid[0:H, 0:W].astype(float)
    z = 0.5 + 0.0004 * u + 0.005 * np.sin(v / 7.0) + (u > 50) * 0.05  # a depth step at u = 50 (flying pixels)
    xyz = np.dstack([(u - W / 2) * 0.001 * z, (v - H / 2) * 0.001 * z, z]) + rng.normal(0, 2e-5, (H, W, 3))
    xyz[rng.random((H, W)) < 0.005] = np.nan  # holes
    xyz[20:30, 10:25] = np.nan
    vp = np.array([0.01, -0.02, 0.0])
    extra = rng.random((H, W)) < 0.02 if with_extra else None
    want_xyz, want_n = _numpy_filter(xyz, vp, 0.004, margin, extra)
    got_xyz, got_n = filter_range_map(xyz, vp, max_jump=0.004, margin=margin, extra_drop=extra)
    assert np.array_equal(got_xyz, want_xyz, equal_nan=True)
    assert np.array_equal(got_n, want_n, equal_nan=True)
    assert np.isfinite(got_xyz[:, :, 0]).sum() > 0.5 * H * W  # not everything dropped
    assert not np.isfinite(got_xyz[:, 50:52, 0]).any()  # the step's flying pixels are gone


@pytest.mark.parametrize("level", [0, 1, 6])
def test_npz_levels_read_back_exactly(tmp_path, level):
    a = {"f": np.random.default_rng(1).random((40, 30)).astype(np.float32), "b": np.arange(12) % 3 == 0}
    a["f"][3, 4] = np.nan
    atomic_save_npz(tmp_path / "m.npz", level=level, **a)
    with np.load(tmp_path / "m.npz") as z:
        assert all(np.array_equal(z[k], a[k], equal_nan=True) and z[k].dtype == a[k].dtype for k in a)


def test_decode_command_starts_without_heavy_modules(tmp_path):
    """``rangekit decode`` of a Gray-code folder imports neither scipy.spatial, Open3D, the simulator nor the
    app layer (the projector's own patterns as the captures: every column decodes to itself)."""
    spec = make_pattern_spec("graycode", (64, 32))
    folder = tmp_path / "cap"
    folder.mkdir()
    for i, frame in enumerate(spec.frames()):
        write_png(folder / f"{i:03d}.png", frame)
    (folder / "patterns.json").write_text(json.dumps(spec.to_dict()))
    code = ("import sys; from rangekit.cli import main; "
            f"rc = main(['decode', {str(folder)!r}, '--pattern', {str(folder / 'patterns.json')!r}, "
            f"'--integer', '--out', {str(tmp_path / 'maps.npz')!r}]); "
            "print(rc, [m for m in ('scipy.spatial', 'open3d', 'rangekit.sim', 'rangekit.app', 'rangekit.surface') "
            "if m in sys.modules])")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "0 []"
    with np.load(tmp_path / "maps.npz") as z:
        assert np.array_equal(z["proj_col"], np.broadcast_to(np.arange(64, dtype=np.float32), (32, 64)))
