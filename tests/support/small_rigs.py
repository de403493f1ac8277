"""Small simulated rigs shared by tests: the default rig at a fraction of its resolution."""

from dataclasses import replace

from rangekit.rig.rig_file import Rig
from rangekit.sim import default_rig


def small_rig() -> Rig:
    """The default simulated rig's camera at 320x256 (same pose and lens), its projector and turntable: the
    suite's session rig (the ``small_rig`` fixture)."""
    r = default_rig()
    return Rig(cameras=(r.camera.resized(320, 256),), projector=r.projector, T_world_table=r.T_world_table)


def small_projector_rig():
    """The default simulated rig with a 320x256 camera and a 320x200 projector (same poses and lenses)."""
    r = default_rig()
    return replace(r, cameras=(r.camera.resized(320, 256),), projector=r.projector.resized(320, 200))
