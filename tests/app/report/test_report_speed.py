"""The report's and the evaluation's fast paths against the straightforward code they replace:
every one must give the same bits (colours, z-buffer winners, normal sums, k-d tree neighbours, depth edges),
and the kept mesh casts must be the casts."""

from __future__ import annotations

import gc

import numpy as np
import pytest
import trimesh

from rangekit.rendering.snapshot import fit_camera, render_cloud
from rangekit.rendering.hits import HITS_PER_MESH, _cast_mesh, raycast_mesh
from rangekit.colour import colour_table, colourise
from rangekit.geometry import apply_T
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.quality import view_disagreement, view_trees


def _colourise_reference(values, vmin, vmax, cmap="turbo", nan_colour=(255, 255, 255)):
    """The float64 formula colourise implements: table[rint(255 clip((v - vmin) / span, 0, 1))]."""
    v = np.asarray(values, dtype=np.float64)
    span = vmax - vmin
    with np.errstate(invalid="ignore"):
        t = np.clip((v - vmin) / span if span > 0 else (v > vmin).astype(np.float64), 0.0, 1.0)
    bad = ~np.isfinite(v)
    out = colour_table(cmap)[np.rint(np.where(bad, 0.0, t) * 255).astype(np.intp)].copy()
    out[bad] = np.asarray(nan_colour, dtype=np.float64).astype(np.uint8)
    return out


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32])
@pytest.mark.parametrize("cmap", ["turbo", "viridis", "grey"])
def test_colourise_matches_the_formula_bit_for_bit(dtype, cmap):
    rng = np.random.default_rng(3)
    v = (rng.normal(0.5, 0.6, (37, 41)) * (100 if dtype == np.int32 else 1)).astype(dtype)
    if dtype != np.int32:
        v.flat[::7] = np.nan
        v.flat[3::11] = np.inf
        v.flat[5::13] = -np.inf
        v.flat[1] = 0.5 / 255   # exactly half way between two entries: rint's ties to even
    for lo, hi in ((0.0, 1.0), (0.2, 0.2), (-3.0, 250.0)):
        got = colourise(v, lo, hi, cmap=cmap, nan_colour=(12.7, 200, 3))
        assert got.dtype == np.uint8 and got.shape == v.shape + (3,)
        assert np.array_equal(got, _colourise_reference(v, lo, hi, cmap, (12.7, 200, 3)))
    assert np.array_equal(colourise(np.float64(0.5), 0, 1), colour_table("turbo")[128])   # a 0-d value


def _painter_reference(points, camera, r):
    """Brute force: paint every point's (2r+1)^2 square far to near, one point at a time, ties to the earlier
    point (painted last); returns the (H, W) index of the point seen at each pixel, -1 where none."""
    H, W = camera.height, camera.width
    p_cam = apply_T(camera.T_cam_world, points)
    uv = np.rint(camera.project_cam(p_cam))
    owner = np.full((H, W), -1)
    finite = [i for i in range(len(points)) if np.all(np.isfinite(uv[i]))]
    for i in sorted(finite, key=lambda i: (-p_cam[i, 2], -i)):
        u, v = int(uv[i, 0]), int(uv[i, 1])
        owner[max(0, v - r):max(0, v + r + 1), max(0, u - r):max(0, u + r + 1)] = i
    return owner


@pytest.mark.parametrize("r", [0, 1, 2])
def test_render_cloud_z_buffer_matches_a_painter(r):
    rng = np.random.default_rng(r)
    P = rng.uniform(-0.05, 0.05, (1500, 3))
    P[::50] = P[1::50]               # duplicated points: equal depth at one pixel, the first one wins
    P[7] = [np.nan, 0.0, 0.0]
    values = np.arange(len(P), dtype=np.float64)
    cam = fit_camera(P[np.isfinite(P).all(1)], azimuth=0.4, elevation=0.3, size=(40, 30))
    img = render_cloud(P, cam, values=values, vmin=0, vmax=len(P), cmap="turbo", point_px=r)
    owner = _painter_reference(P, cam, r)
    want = np.full(img.shape, 255, np.uint8)
    seen = owner >= 0
    want[seen] = colourise(values[owner[seen]], 0, len(P), cmap="turbo")
    assert np.array_equal(img, want)


def test_normal_sums_are_the_sums_of_add_at():
    tm = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    rng = np.random.default_rng(0)
    mesh = TriangleMesh(tm.vertices + rng.normal(0, 1e-3, tm.vertices.shape), tm.faces[rng.permutation(len(tm.faces))])
    V, F = mesh.vertices, mesh.triangles
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    want = np.zeros_like(V)
    for k in range(3):
        np.add.at(want, F[:, k], fn)
    assert np.array_equal(mesh.normal_sums, want)


def test_view_disagreement_from_shared_trees_is_the_same():
    rng = np.random.default_rng(1)
    V = rng.uniform(0, 0.02, (400, 3)) * [1, 1, 0]
    N = np.tile([0.0, 0.0, 1.0], (len(V), 1))
    views = [rng.uniform(0, 0.02, (3000, 3)) * [1, 1, 0] + [0, 0, dz] for dz in (0.0, 1e-4, -2e-4)]
    views.append(np.full((2, 3), np.nan))          # a view without points
    a = view_disagreement(V, N, views, radius=1e-3)
    b = view_disagreement(V, N, radius=1e-3, trees=view_trees(views))
    assert np.array_equal(a.offsets, b.offsets, equal_nan=True)
    assert np.allclose(a.offsets[1][np.isfinite(a.offsets[1])] - a.offsets[0][np.isfinite(a.offsets[1])], 1e-4)


def test_mesh_casts_are_kept_per_mesh_and_camera():
    tm = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    mesh = TriangleMesh(tm.vertices, tm.faces)
    cams = [fit_camera(mesh.vertices, azimuth=a, elevation=0.3, size=(48, 40)) for a in np.linspace(0, 6, 12)]
    first = raycast_mesh(mesh, cams[0])
    again = raycast_mesh(mesh, fit_camera(mesh.vertices, azimuth=0.0, elevation=0.3, size=(48, 40)))
    assert again is first and not first.xyz.flags.writeable
    fresh = _cast_mesh(mesh, cams[0])
    for name in ("hit", "xyz", "normal", "triangle", "bary", "smooth_normal"):
        assert np.array_equal(getattr(first, name), getattr(fresh, name), equal_nan=True)
    assert raycast_mesh(mesh, cams[1]) is not first
    for cam in cams:                                # more cameras than kept: the oldest ones go
        raycast_mesh(mesh, cam)
    from rangekit.rendering import hits as snapshot_hits

    assert len(snapshot_hits._HITS[mesh]) == HITS_PER_MESH
    other = TriangleMesh(tm.vertices * 2, tm.faces)  # another mesh, same camera: cast anew
    assert not np.array_equal(raycast_mesh(other, cams[0]).xyz, first.xyz, equal_nan=True)
    n = len(snapshot_hits._HITS)
    del other
    gc.collect()
    assert len(snapshot_hits._HITS) == n - 1        # kept only while the mesh lives


def test_depth_edges_on_the_cast_box_are_the_whole_image_edges():
    from rangekit.sim.truth.view_errors import _MARGIN, _box, _box_edges, depth_edges

    class Cam:
        width, height = 90, 70

    rng = np.random.default_rng(2)
    depth = np.full((70, 90), np.nan)
    depth[10:50, 20:75] = 0.5 + 0.001 * rng.standard_normal((40, 55))
    depth[25:35, 30:40] = 0.4                          # a step: a depth edge inside
    uv = np.column_stack([rng.integers(22, 70, 300), rng.integers(12, 45, 300)])
    box = _box(uv, Cam, _MARGIN)
    cast = np.full_like(depth, np.nan)
    cast[box] = depth[box]                             # as a whole-image cast over the box leaves it
    assert np.array_equal(_box_edges(cast[box], box, Cam), depth_edges(cast)[box])
    edge_uv = np.column_stack([np.arange(0, 40), np.zeros(40, int)])   # at the image border
    box = _box(edge_uv, Cam, _MARGIN)
    cast = np.full_like(depth, np.nan)
    cast[box] = 0.5
    assert np.array_equal(_box_edges(cast[box], box, Cam), depth_edges(cast)[box])


def test_the_truth_cast_through_a_cropped_camera_is_the_whole_casts_box():
    from rangekit.sim import default_rig, default_scene
    from rangekit.sim.scene.raycast import cast_view
    from rangekit.sim.truth.view_errors import _truth_in_box

    rig = default_rig()
    cam = rig.camera.resized(320, 256)
    world = default_scene().world_mesh(rig.T_world_rotated(0.3))
    whole = cast_view(world, cam, rig.projector)
    box = (slice(60, 200), slice(90, 250))
    part, _ = _truth_in_box(world, cam, rig.projector, box)
    for name in ("depth", "proj_col", "object_id"):
        assert np.array_equal(getattr(part, name), getattr(whole, name)[box], equal_nan=True), name
