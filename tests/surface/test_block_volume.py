"""The sparse TSDF volume's rim extension (issue 51, :func:`rangekit.surface.block_volume.extend_depth`): each view's
depth carried a few pixels past its data's rim, so the fused surface reaches past the points as far as the observed
cut allows, against an exact sphere."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.errors import InputError


def test_extend_depth_gives_each_empty_pixel_near_the_data_its_nearest_measured_depth():
    from scipy.ndimage import distance_transform_edt

    from rangekit.surface.block_volume import extend_depth

    rng = np.random.default_rng(1)
    z = np.zeros((120, 160), np.float32)
    yy, xx = np.mgrid[:120, :160]
    z[(yy - 50) ** 2 + (xx - 70) ** 2 < 30 ** 2] = 0.4
    z[rng.random(z.shape) < 0.05] = 0.0                   # holes inside, as a decode leaves them
    z[z > 0] += rng.normal(0, 1e-3, np.count_nonzero(z > 0)).astype(np.float32)
    out = extend_depth(z, 4)
    d, (r, c) = distance_transform_edt(z == 0, return_indices=True)   # the whole image's answer
    near = (z == 0) & (d <= 4)
    expect = z.copy()
    expect[near] = z[r[near], c[near]]
    assert np.array_equal(out, expect)                   # the box it works in changes no pixel
    assert np.array_equal(out[z > 0], z[z > 0]) and np.all(out[d > 4] == 0)
    assert np.array_equal(extend_depth(z, 0), z) and not np.any(extend_depth(np.zeros_like(z), 4))


@pytest.mark.parametrize("bad", [-1, 65, 2.5])
def test_a_block_volume_refuses_a_wrong_extension(bad):
    from rangekit.surface.block_volume import BlockVolume

    with pytest.raises(InputError, match="extend_px"):
        BlockVolume(0.001, extend_px=bad)


def _sphere_views(rig, centre, radius):
    """Three views of the sphere (the camera turned about its centre), the data of each stopping at a rim: every
    pixel whose surface point lies below the sphere's centre (world -y of the camera's rows) left empty, as a
    shadow's edge leaves it. Yields (depth, camera)."""
    from rangekit.geometry import make_T

    camera0 = rig.camera
    for deg in (-20.0, 0.0, 20.0):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        camera = camera0.with_pose(make_T(R, centre - R @ centre) @ camera0.T_world_cam)
        o, rays = camera.rays(camera.pixel_grid())
        oc = o[0] - centre
        b = rays @ oc
        disc = b * b - (oc @ oc - radius * radius)
        t = -b - np.sqrt(np.where(disc > 0, disc, np.nan))
        P = o[0] + t[:, None] * rays
        z = t * (rays @ camera.T_world_cam[:3, 2])
        down = camera0.T_world_cam[:3, 1]                  # the image's rows grow along the camera's y
        z[(P - centre) @ down > 0] = np.nan
        yield z.reshape(camera.height, camera.width), camera


def test_the_extended_volume_reaches_past_the_rim_of_the_data_and_keeps_the_surface_where_it_is():
    """A 40 mm sphere whose data stops at a rim in every view (the half beyond its centre left empty): the
    volume's surface without extension stops short of the rim; with 4 px (1 mm at 0.45 m) the true sphere within
    half a millimetre past the rim is covered (a vertex within a voxel), and where the data is the surface is
    as close to the sphere as before."""
    from rangekit.sim import default_rig
    from rangekit.surface.block_volume import BlockVolume

    rig = default_rig()
    camera0 = rig.camera
    centre = camera0.T_world_cam[:3, 3] + 0.45 * camera0.T_world_cam[:3, 2]
    radius, voxel = 0.02, 0.0005
    plain, extended = BlockVolume(voxel), BlockVolume(voxel, extend_px=4)
    for depth, camera in _sphere_views(rig, centre, radius):
        plain.integrate(depth, camera)
        extended.integrate(depth, camera)
    from scipy.spatial import cKDTree

    down, toward = camera0.T_world_cam[:3, 1], -camera0.T_world_cam[:3, 2]
    u = np.random.default_rng(0).normal(size=(200_000, 3))
    S = u / np.linalg.norm(u, axis=1, keepdims=True)
    past = S[(S @ toward > 0.5) & (S @ down * radius > 0.0) & (S @ down * radius < 0.0005)] * radius + centre
    inside = S[(S @ toward > 0.5) & (S @ down * radius < -0.002)] * radius + centre
    covered, off = {}, {}
    for name, volume in (("plain", plain), ("extended", extended)):
        V = np.asarray(volume.mesh().vertices)
        covered[name] = float(np.mean(cKDTree(V).query(past)[0] < voxel))
        mine = V[cKDTree(inside).query(V)[0] < voxel]
        off[name] = float(np.sqrt(np.mean((np.linalg.norm(mine - centre, axis=1) - radius) ** 2)))
    print(f"\nthe sphere 0-0.5 mm past the rim covered: {covered}; RMS where the data is (mm): "
          f"{ {k: round(v * 1e3, 4) for k, v in off.items()} }")
    assert covered["extended"] > 0.99 and covered["plain"] < 0.6
    assert off["extended"] < voxel / 15 and abs(off["extended"] - off["plain"]) < voxel / 200


def test_the_surface_is_the_same_bytes_whatever_the_first_capacity_and_the_hash_map_grows_past_it():
    """The blocks' hash map is allocated at its first capacity and grows when a view needs more: a volume begun
    with room for 4 blocks holds the sphere's (14 of them at 1 mm) and gives the surface, byte for byte, of one
    begun with the default room."""
    from rangekit.sim import default_rig
    from rangekit.surface.block_volume import BlockVolume

    rig = default_rig()
    centre = rig.camera.T_world_cam[:3, 3] + 0.45 * rig.camera.T_world_cam[:3, 2]
    small, default = BlockVolume(0.001, blocks=4), BlockVolume(0.001)
    for depth, camera in _sphere_views(rig, centre, 0.02):
        small.integrate(depth, camera)
        default.integrate(depth, camera)
    used = small._grid.hashmap().size()
    assert used > 2 * 4 and small._grid.hashmap().capacity() >= used == default._grid.hashmap().size()
    a, b = small.surface(), default.surface()
    assert len(a.vertices) > 1000
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)


def test_canonical_mesh_is_one_order_whatever_the_order_given():
    from rangekit.surface.block_volume import canonical_mesh
    from rangekit.surface.mesh import TriangleMesh

    rng = np.random.default_rng(4)
    V = rng.normal(size=(50, 3))
    F = np.array([rng.choice(50, 3, replace=False) for _ in range(80)])
    perm = rng.permutation(50)
    inverse = np.argsort(perm)
    shuffled = TriangleMesh(V[perm], np.roll(inverse[F], 1, axis=1)[rng.permutation(80)])   # turned, reordered
    a, b = canonical_mesh(TriangleMesh(V, F)), canonical_mesh(shuffled)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.triangles, b.triangles)
    assert np.all(np.diff(a.vertices[:, 0]) >= 0)
    # the same triangles, each with its winding: every (corner, next corner) edge of one is one of the other's
    edges = lambda m: {tuple(m.vertices[t[i]]) + tuple(m.vertices[t[(i + 1) % 3]]) for t in m.triangles for i in range(3)}
    assert edges(a) == edges(TriangleMesh(V, F))
    # A vertex repeated at one point (as the grid's marching cubes repeats a few where blocks meet), in either order:
    # made one, the same mesh; a triangle left with two corners at it dropped.
    Vd = np.concatenate([V, V[:1]])
    Fd = np.concatenate([F, [[50, 1, 2], [0, 50, 3]]])
    for first in (Vd, Vd[::-1]):
        perm = np.arange(51) if first is Vd else np.arange(51)[::-1]
        inv = np.argsort(perm)
        got = canonical_mesh(TriangleMesh(first, inv[Fd]))
        assert np.array_equal(got.vertices, a.vertices) and len(got.triangles) == 81
    assert np.array_equal(got.triangles, canonical_mesh(TriangleMesh(Vd, Fd)).triangles)
