"""One Open3D ray-casting scene per triangle set: the single place that builds a ``RaycastingScene``.

Open3D's scene is float32 (BVH): callers that care about precision pass coordinates relative to the
mesh's centre and recompute hits in float64 against the triangle it reports. :func:`mesh_scene` keeps that
centred scene per mesh object, so ten renders of one mesh (the report) or two distance queries against
one true surface build its BVH once (on the 910k-triangle mesh of the 12-view scan building it takes 0.41 s,
one 640x480 cast 12 ms: ``benchmarks/app/bench_process_parts.py SESSION``).

Every query goes through :func:`query_scene`: Open3D holds Python's GIL for the whole of a query (2 M rays: no
other Python thread ran for 1.95 s), so a query on one thread (the truth's casts in a scan's streaming
processing) would stop another (the capture's) for as long; in chunks of :data:`RAYS_PER_QUERY` the others wait
at most a few milliseconds, for the same answer and no loss of speed (1 M rays: 0.36 s whole or in chunks).
"""

from __future__ import annotations

import threading
import weakref

import numpy as np

__all__ = ["RAYS_PER_QUERY", "raycasting_scene", "mesh_scene", "query_scene"]

#: Rays (or points) per Open3D call in :func:`query_scene`: 1.5 ms of one core cast, 7 ms a closest-point query.
RAYS_PER_QUERY = 1 << 12

_SCENES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_LOCK = threading.Lock()


def mesh_scene(mesh) -> tuple[object, np.ndarray]:
    """``(scene, centre)``: the ray-casting scene of ``mesh`` (a TriangleMesh) in coordinates relative to
    ``centre`` (3,) metres, the middle of its bounding box; built on the first call and kept as long as
    the mesh object lives (meshes are immutable). Thread-safe."""
    with _LOCK:
        hit = _SCENES.get(mesh)
        if hit is None:
            c = (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0)) / 2
            hit = (raycasting_scene(mesh.vertices - c, mesh.triangles), c)
            _SCENES[mesh] = hit
        return hit


def raycasting_scene(vertices: np.ndarray, triangles: np.ndarray):
    """An ``open3d.t.geometry.RaycastingScene`` holding one triangle mesh (imports open3d).

    Parameters
    ----------
    vertices : (V, 3) float metres (converted to float32; subtract a centre first for precision).
    triangles : (F, 3) int indices into ``vertices``.

    Returns
    -------
    open3d.t.geometry.RaycastingScene, ready for ``cast_rays``, ``compute_distance`` and
    ``compute_closest_points`` with float32 tensors in the same coordinates.
    """
    import open3d as o3d  # imported here: it takes ~2 s and most of rangekit never needs it

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(vertices).astype(np.float32)),
                        o3d.core.Tensor(np.asarray(triangles).astype(np.uint32)))
    return scene


def query_scene(scene, method: str, queries: np.ndarray):
    """``scene.<method>(queries)`` (``"cast_rays"``, ``"compute_closest_points"``, ``"compute_distance"``, ...)
    run :data:`RAYS_PER_QUERY` rows at a time, so that other Python threads run between the calls (module doc).

    ``queries``: (N, 6) rays or (N, 3) points, float32 in the scene's coordinates. Returns what the method returns
    as NumPy: a dict of arrays (N, ...) for a dict-returning method, else one array (N, ...)."""
    import open3d as o3d  # imported here: it takes ~2 s and most of rangekit never needs it

    q = np.ascontiguousarray(queries, dtype=np.float32)
    call = getattr(scene, method)
    parts = [call(o3d.core.Tensor(q[i:i + RAYS_PER_QUERY])) for i in range(0, max(len(q), 1), RAYS_PER_QUERY)]
    if isinstance(parts[0], dict):
        return {key: np.concatenate([p[key].numpy() for p in parts]) for key in parts[0]}
    return np.concatenate([p.numpy() for p in parts])
