"""One Open3D ray-casting scene per triangle set: the single place that builds a ``RaycastingScene``.

Open3D's scene is float32 (BVH): callers that care about precision pass coordinates relative to the
mesh's centre and recompute hits in float64 against the triangle it reports.
"""

from __future__ import annotations

import numpy as np

__all__ = ["raycasting_scene"]


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
