"""Simulated hardware with exact ground truth: scenes, ray casting, image formation, devices.

``from rangekit.sim import SimRig, default_scene`` gives a projector-camera-turntable rig that produces
the same captures as the hardware, plus the truth (depth, points, normals, projector coordinates). The names
below load on first use (rangekit._runtime.lazy, as every rangekit package re-exports).
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
