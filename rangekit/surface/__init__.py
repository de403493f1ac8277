"""Surfaces: point clouds, triangle meshes, fusion of views (Poisson, TSDF), watertight repair, ray casting.

The names below are loaded on first use (PEP 562): importing one module of this package, e.g.
``rangekit.surface.fusion`` in Poisson's child process, does not import the others (the closing's numba
kernels and scipy's k-d trees: 90 MB resident and 0.2 s that Poisson never uses)."""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
