"""Surfaces: point clouds, triangle meshes, fusion of views (Poisson, TSDF), watertight repair, ray casting.

The names below are loaded on first use (PEP 562): importing one module of this package, e.g.
``rangekit.surface.fusion`` in Poisson's child process, does not import the others (the closing's numba
kernels and scipy's k-d trees: 90 MB resident and 0.2 s that Poisson never uses)."""

from rangekit._runtime.lazy import lazy_exports

_MODULE_OF = {
    **dict.fromkeys(("PointCloud", "affine_dimension", "estimate_normals", "merge_clouds", "orient_normals_to_sensor",
                     "oriented_normals_cloud", "spread_problem", "transform_cloud", "voxel_downsample"), "cloud"),
    "to_open3d": "convert",
    **dict.fromkeys(("poisson_input_problem", "poisson_mesh", "tsdf_fuse"), "fusion"),
    **dict.fromkeys(("TriangleMesh", "distance_to_surface", "mesh_from_open3d", "signed_volume"), "mesh"),
    "raycasting_scene": "raycast",
    **dict.fromkeys(("clean_mesh", "make_watertight"), "watertight"),
}

__all__ = ["PointCloud", "to_open3d", "voxel_downsample", "estimate_normals", "orient_normals_to_sensor",
           "oriented_normals_cloud", "transform_cloud", "merge_clouds", "TriangleMesh", "mesh_from_open3d",
           "signed_volume", "distance_to_surface", "poisson_mesh", "tsdf_fuse", "make_watertight", "clean_mesh",
           "raycasting_scene", "affine_dimension", "spread_problem", "poisson_input_problem"]

__getattr__, __dir__ = lazy_exports(__name__, _MODULE_OF, __all__)
