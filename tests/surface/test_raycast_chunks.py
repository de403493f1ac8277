"""rangekit.surface.raycast.query_scene: Open3D's queries in chunks (so other Python threads run between them)
give exactly what one call gives."""

from __future__ import annotations

import numpy as np

from rangekit.surface.raycast import RAYS_PER_QUERY, query_scene, raycasting_scene


def _sphere_scene():
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_sphere(0.05, 40)
    return raycasting_scene(np.asarray(m.vertices), np.asarray(m.triangles))


class _Counting:
    """A scene that counts the calls made to it (each one holds the GIL)."""

    def __init__(self, scene):
        self.scene, self.calls = scene, []

    def __getattr__(self, name):
        def call(q):
            self.calls.append(len(q))
            return getattr(self.scene, name)(q)
        return call


def test_chunked_queries_are_the_whole_query():
    import open3d as o3d

    rng = np.random.default_rng(0)
    n = 2 * RAYS_PER_QUERY + 123                   # two whole chunks and a part
    rays = np.zeros((n, 6), np.float32)
    rays[:, :3] = rng.normal(0, 0.01, (n, 3)) + [0, 0, -0.2]
    rays[:, 3:] = rng.normal(0, 0.2, (n, 3)) + [0, 0, 1]
    scene = _Counting(_sphere_scene())
    got = query_scene(scene, "cast_rays", rays)
    assert scene.calls == [RAYS_PER_QUERY, RAYS_PER_QUERY, 123]
    whole = scene.scene.cast_rays(o3d.core.Tensor(rays))
    for key in ("t_hit", "primitive_ids", "primitive_uvs", "primitive_normals"):
        assert np.array_equal(got[key], whole[key].numpy()), key
    assert 0.3 < np.isfinite(got["t_hit"]).mean() < 1         # hits and misses both
    points = rays[:, :3]
    dist = query_scene(scene, "compute_distance", points)
    assert dist.shape == (n,) and np.array_equal(dist, scene.scene.compute_distance(o3d.core.Tensor(points)).numpy())
    assert np.allclose(dist, np.abs(np.linalg.norm(points, axis=1) - 0.05), atol=2e-4)   # the sphere's truth
    assert query_scene(scene, "cast_rays", np.zeros((0, 6), np.float32))["t_hit"].shape == (0,)
