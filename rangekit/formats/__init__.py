"""Files a user keeps: point clouds (PLY, PCD, XYZ, NPY) and meshes (PLY, OBJ, STL), with one PLY reader and writer."""

from rangekit.formats.clouds import CLOUD_READERS, CLOUD_WRITERS, RangeGrid, load_cloud, load_range_grid, save_cloud
from rangekit.formats.meshes import MESH_FORMATS, load_mesh_file, save_mesh
from rangekit.formats.ply import cloud_ply_bytes, mesh_ply_bytes, read_ply

__all__ = ["load_cloud", "save_cloud", "CLOUD_READERS", "CLOUD_WRITERS", "RangeGrid", "load_range_grid",
           "load_mesh_file", "save_mesh", "MESH_FORMATS", "read_ply", "cloud_ply_bytes", "mesh_ply_bytes"]
