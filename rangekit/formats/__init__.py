"""Files a user keeps: point clouds (PLY, PCD, XYZ, NPY) and meshes (PLY, OBJ, STL) with one PLY reader and
writer, capture folders, poses.json, ToF capture folders, scan sessions (session.json, summary.json).

The names below are loaded on first use (PEP 562): importing one module of this package, e.g.
``rangekit.formats.capture`` for ``rangekit decode``, does not import the others (clouds and meshes pull in
``rangekit.surface`` and scipy.spatial, about 0.6 s)."""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
