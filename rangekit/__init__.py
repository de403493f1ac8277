"""rangekit: active 3D scanning, from the rig's captures to one watertight mesh.

The functions a notebook reaches for first are here (README "In Python")::

    import rangekit as rk
    cloud = rk.load_cloud("scan.e57")                  # .ply .pcd .xyz .npy .e57
    result = rk.icp(source, target)                    # arrays, PointClouds, Open3D or trimesh objects
    mesh = rk.poisson_mesh(cloud)
    rk.save_mesh("mesh.glb", mesh)                     # .ply .obj .stl .glb
    picture = rk.render(mesh).image                    # (H, W, 3) uint8

They are imported on first use (module ``__getattr__``), so ``import rangekit`` stays fast and loads no
heavy dependency; everything else is in its module (``rangekit.camera``, ``rangekit.sim``...). The main job:
``rk.scan(rk.ScanOptions(out="scan1"))``, ``rk.process("scan1")``; one capture to a cloud:
``rk.reconstruct("capture_dir")``. A subpackage is reached the same way (``rk.photometric``, ``rk.sim``).
"""

import os as _os
import sys as _sys

if _sys.argv[:1] == ["-m"]:
    # ``python -m rangekit``, while Python still imports this package to find its __main__: a Ctrl-C here
    # would end in a traceback before the command line's own handling starts (rangekit.cli replaces this).
    import signal as _signal

    def _interrupted_while_starting(signum, frame):
        _sys.stderr.write("rangekit: interrupted\n")
        _sys.stderr.flush()
        _os._exit(130)

    if _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
        _signal.signal(_signal.SIGINT, _interrupted_while_starting)

__version__ = "0.1.0"

# numba's parallel kernels run on OpenMP, whose idle threads spin between kernels by default; beside
# PNG reading and Open3D's Poisson on the other core that spinning costs CPU (the decode stage of the
# 12-view scan: 11.1-11.7 CPU-s passive against 11.9-12.7 by default, 16.8-37.8 with ACTIVE on a loaded
# machine; ``OMP_WAIT_POLICY=X python benchmarks/coded/bench_decode_stage.py SESSION``, alternating). Set before
# any OpenMP runtime starts; a user's own setting wins. See rangekit._runtime.threads.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# The one re-export mechanism of rangekit's packages: each name of __init__.pyi loads on first use
# (rangekit._runtime.lazy.attach_stub), so ``import rangekit`` stays light.
from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
__all__ = ["__version__", *__all__]
