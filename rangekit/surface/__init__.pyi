"""The names of ``rangekit.surface``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .cloud import (PointCloud as PointCloud, voxel_downsample as voxel_downsample,
    estimate_normals as estimate_normals, orient_normals_to_sensor as orient_normals_to_sensor,
    oriented_normals_cloud as oriented_normals_cloud, transform_cloud as transform_cloud,
    merge_clouds as merge_clouds, affine_dimension as affine_dimension, spread_problem as spread_problem)
from .convert import to_open3d as to_open3d
from .mesh import (TriangleMesh as TriangleMesh, mesh_from_open3d as mesh_from_open3d,
    signed_volume as signed_volume, distance_to_surface as distance_to_surface)
from .fusion import (poisson_mesh as poisson_mesh, tsdf_fuse as tsdf_fuse,
    poisson_input_problem as poisson_input_problem)
from .watertight import make_watertight as make_watertight, clean_mesh as clean_mesh
from .raycast import raycasting_scene as raycasting_scene
