"""rangekit: active 3D scanning, from the rig's captures to one watertight mesh.

The functions a notebook reaches for first are here (README "In Python")::

    import rangekit as rk
    cloud = rk.load_cloud("scan.e57")                  # .ply .pcd .xyz .npy .e57
    result = rk.icp(source, target)                    # arrays, PointClouds, Open3D or trimesh objects
    mesh = rk.poisson_mesh(cloud)
    rk.save_mesh("mesh.glb", mesh)                     # .ply .obj .stl .glb
    picture = rk.render(mesh).image                    # (H, W, 3) uint8

They are imported on first use (module ``__getattr__``), so ``import rangekit`` stays fast and loads no
heavy dependency; everything else is in its module (``rangekit.camera``, ``rangekit.sim``...).
"""

import os as _os

__version__ = "0.1.0"

# numba's parallel kernels run on OpenMP, whose idle threads spin between kernels by default; beside
# PNG reading and Open3D's Poisson on the other core that spinning costs CPU (the decode stage of the
# 12-view scan: 11.1-11.7 CPU-s passive against 11.9-12.7 by default, 16.8-37.8 with ACTIVE on a loaded
# machine; ``OMP_WAIT_POLICY=X python benchmarks/coded/bench_decode_stage.py SESSION``, alternating). Set before
# any OpenMP runtime starts; a user's own setting wins. See rangekit._runtime.threads.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# name -> module that defines it; imported on first access (PEP 562), so ``import rangekit`` stays light.
_LAZY = {
    "load_cloud": "rangekit.formats.clouds", "save_cloud": "rangekit.formats.clouds",
    "load_range_grid": "rangekit.formats.clouds",
    "load_mesh": "rangekit.formats.meshes", "save_mesh": "rangekit.formats.meshes",
    "PointCloud": "rangekit.surface.cloud", "TriangleMesh": "rangekit.surface.mesh",
    "as_cloud": "rangekit.surface.convert", "as_mesh": "rangekit.surface.convert",
    "from_open3d": "rangekit.surface.convert", "from_trimesh": "rangekit.surface.convert",
    "to_trimesh": "rangekit.surface.convert", "to_open3d": "rangekit.surface.convert",
    "estimate_normals": "rangekit.surface.cloud", "voxel_downsample": "rangekit.surface.cloud",
    "merge_clouds": "rangekit.surface.cloud", "transform_cloud": "rangekit.surface.cloud",
    "poisson_mesh": "rangekit.surface.fusion", "make_watertight": "rangekit.surface.watertight",
    "icp": "rangekit.registration.icp", "IcpOptions": "rangekit.registration.icp",
    "register_views": "rangekit.registration.multiview", "MultiViewOptions": "rangekit.registration.multiview",
    "render": "rangekit.app.commands.picture",
    "scan": "rangekit.app.scan.scan", "ScanOptions": "rangekit.app.scan.options", "ScanResult": "rangekit.app.scan.scan",
    "process": "rangekit.app.scan.scan", "ProcessOptions": "rangekit.app.process.options",
}
__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'rangekit' has no attribute {name!r}")
    import importlib

    attr = "load_mesh_file" if name == "load_mesh" else name
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value   # the next access is a plain attribute
    return value


def __dir__():
    return sorted([*globals(), *_LAZY])
