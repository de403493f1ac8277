"""The names of ``rangekit``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .formats.clouds import load_cloud as load_cloud, save_cloud as save_cloud, load_range_grid as load_range_grid
from .formats.meshes import load_mesh as load_mesh, save_mesh as save_mesh
from .rig.rig_file import load_rig as load_rig, save_rig as save_rig, Rig as Rig
from .surface.cloud import (PointCloud as PointCloud, estimate_normals as estimate_normals,
    voxel_downsample as voxel_downsample, merge_clouds as merge_clouds, transform_cloud as transform_cloud)
from .surface.mesh import TriangleMesh as TriangleMesh
from .surface.convert import (as_cloud as as_cloud, as_mesh as as_mesh, from_open3d as from_open3d,
    from_trimesh as from_trimesh, to_trimesh as to_trimesh, to_open3d as to_open3d)
from .surface.fusion import poisson_mesh as poisson_mesh
from .surface.watertight import make_watertight as make_watertight
from .registration.icp import icp as icp, IcpOptions as IcpOptions
from .registration.multiview import register_views as register_views, MultiViewOptions as MultiViewOptions
from .app.commands.picture import render as render
from .app.commands.reconstruct import reconstruct as reconstruct
from .app.commands.register import register as register
from .app.commands.photometric import photometric_folder as photometric_folder
from .photometric.calibrated import photometric_stereo as photometric_stereo
from .app.scan.scan import scan as scan, ScanResult as ScanResult, process as process
from .app.scan.options import ScanOptions as ScanOptions
from .app.process.options import ProcessOptions as ProcessOptions
