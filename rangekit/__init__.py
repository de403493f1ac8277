"""rangekit: active 3D scanning, from the rig's captures to one watertight mesh.

Import what you need from its modules (``rangekit.camera``, ``rangekit.geometry``, ``rangekit.sim``...);
importing the package itself is fast and loads no heavy dependency.
"""

import os as _os

__version__ = "0.1.0"

# numba's parallel kernels run on OpenMP, whose idle threads spin between kernels by default; beside
# PNG reading and Open3D's Poisson on the other core that spinning costs CPU (the decode stage of the
# 12-view scan: 11.1-11.7 CPU-s passive against 11.9-12.7 by default, 16.8-37.8 with ACTIVE on a loaded
# machine; ``OMP_WAIT_POLICY=X python benchmarks/bench_decode_stage.py SESSION``, alternating). Set before
# any OpenMP runtime starts; a user's own setting wins. See rangekit.threads.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
