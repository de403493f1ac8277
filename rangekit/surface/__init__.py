"""Surfaces: point clouds, triangle meshes, fusion of views (Poisson, TSDF), watertight repair, ray casting."""

from rangekit.surface.cloud import (PointCloud, affine_dimension, estimate_normals, merge_clouds,
                                    orient_normals_to_sensor, oriented_normals_cloud, spread_problem, to_open3d,
                                    transform_cloud, voxel_downsample)
from rangekit.surface.fusion import poisson_input_problem, poisson_mesh, tsdf_fuse
from rangekit.surface.mesh import TriangleMesh, distance_to_surface, mesh_from_open3d, signed_volume
from rangekit.surface.raycast import raycasting_scene
from rangekit.surface.watertight import clean_mesh, make_watertight

__all__ = ["PointCloud", "to_open3d", "voxel_downsample", "estimate_normals", "orient_normals_to_sensor",
           "oriented_normals_cloud", "transform_cloud", "merge_clouds", "TriangleMesh", "mesh_from_open3d",
           "signed_volume", "distance_to_surface", "poisson_mesh", "tsdf_fuse", "make_watertight", "clean_mesh",
           "raycasting_scene", "affine_dimension", "spread_problem", "poisson_input_problem"]
