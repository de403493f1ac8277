"""The objects users already hold, as rangekit clouds and meshes, and back.

:func:`as_cloud` and :func:`as_mesh` are the one converter each, applied at the entry of every public
function that takes a cloud or a mesh (``icp``, ``register_views``, ``poisson_mesh``, ``render``...). They
accept rangekit's own types, numpy arrays, ``open3d.geometry.PointCloud`` / ``TriangleMesh`` and
``trimesh.Trimesh`` / ``PointCloud`` / ``Scene``; anything else is an InputError naming the type found.
Open3D and trimesh objects are recognised by their class's module, so neither library is imported
here unless the object came from it. :func:`from_open3d` and :func:`from_trimesh` convert one object of
those libraries; :func:`to_open3d` and :func:`to_trimesh` are the way back, for both kinds.
"""

from __future__ import annotations

import numpy as np

from rangekit._runtime.arguments import check_text
from rangekit.errors import ArgumentTypeError, InputError
from rangekit.surface.cloud import PointCloud
from rangekit.surface.cloud import cloud_to_open3d as _cloud_to_open3d
from rangekit.surface.mesh import TriangleMesh, mesh_from_open3d
from rangekit.surface.quality import vertex_normals

__all__ = ["as_cloud", "as_mesh", "from_open3d", "from_trimesh", "to_open3d", "to_trimesh", "CLOUD_KINDS", "MESH_KINDS"]

CLOUD_KINDS = ("an (N, 3) array of points in metres (or (N, 6) with normals), a rangekit PointCloud or TriangleMesh, an "
               "open3d.geometry.PointCloud or TriangleMesh, or a trimesh.PointCloud or Trimesh")
MESH_KINDS = ("a rangekit TriangleMesh, a (vertices (V, 3), triangles (F, 3)) pair, an "
              "open3d.geometry.TriangleMesh, or a trimesh.Trimesh or Scene")


def _library(x) -> str:
    """'open3d', 'trimesh' or '' from the module of ``x``'s class (no import of either library)."""
    module = type(x).__module__ or ""
    return module.split(".")[0] if module.split(".")[0] in ("open3d", "trimesh") else ""


def _type_name(x) -> str:
    return f"{type(x).__module__}.{type(x).__qualname__}"


def from_open3d(x) -> PointCloud | TriangleMesh:
    """A PointCloud of an ``open3d.geometry.PointCloud`` (points, colours, normals; float64) or a
    TriangleMesh of an ``open3d.geometry.TriangleMesh`` (vertices, triangles, vertex colours); also the
    tensor API's ``open3d.t.geometry`` objects (through ``to_legacy()``)."""
    if _library(x) == "open3d" and hasattr(x, "to_legacy") and not hasattr(x, "has_points") \
            and not hasattr(x, "has_triangles"):
        x = x.to_legacy()
    name = type(x).__name__
    if _library(x) == "open3d" and name == "PointCloud":
        colours = np.clip(np.asarray(x.colors), 0.0, 1.0) if x.has_colors() else None
        normals = np.asarray(x.normals).copy() if x.has_normals() else None
        return PointCloud(np.asarray(x.points).copy(), colours, normals)
    if _library(x) == "open3d" and name == "TriangleMesh":
        return mesh_from_open3d(x)
    raise ArgumentTypeError(f"from_open3d(x): expected an open3d.geometry.PointCloud or TriangleMesh, found "
                            f"{_type_name(x)}")


def _rgb01(colours) -> np.ndarray:
    return np.asarray(colours)[:, :3].astype(np.float32) / 255.0


def from_trimesh(x) -> PointCloud | TriangleMesh:
    """A PointCloud of a ``trimesh.PointCloud`` (colours when it has them) or a TriangleMesh of a
    ``trimesh.Trimesh`` / ``trimesh.Scene`` (its geometry concatenated in the scene frame; vertex order
    kept; vertex colours when it has them)."""
    name = type(x).__name__
    if _library(x) == "trimesh" and name == "Scene":
        x = x.to_mesh()
        name = type(x).__name__
    if _library(x) == "trimesh" and name == "PointCloud":
        colours = np.asarray(x.colors)
        return PointCloud(np.asarray(x.vertices, dtype=np.float64),
                          _rgb01(colours) if colours.shape == (len(x.vertices), 4) else None)
    if _library(x) == "trimesh" and name == "Trimesh":
        colours = _rgb01(x.visual.vertex_colors) if x.visual.kind == "vertex" else None
        return TriangleMesh(np.asarray(x.vertices, dtype=np.float64), np.asarray(x.faces, dtype=np.int64), colours)
    raise ArgumentTypeError(f"from_trimesh(x): expected a trimesh.Trimesh, PointCloud or Scene, found {_type_name(x)}")


def to_trimesh(x):
    """A ``trimesh.Trimesh`` of a mesh (:meth:`TriangleMesh.to_trimesh`) or a ``trimesh.PointCloud`` of a
    cloud (8-bit RGBA colours when it has them); anything :func:`as_mesh` / :func:`as_cloud` accepts."""
    if isinstance(x, TriangleMesh) or (_library(x) and type(x).__name__ in ("TriangleMesh", "Trimesh", "Scene")):
        return as_mesh(x, "to_trimesh(x)").to_trimesh()
    import trimesh

    cloud = as_cloud(x, "to_trimesh(x)")
    colours = None
    if cloud.colours is not None:
        colours = np.clip(np.rint(cloud.colours * 255), 0, 255).astype(np.uint8)
    return trimesh.PointCloud(cloud.points, colors=colours)


def to_open3d(x):
    """An ``open3d.geometry.TriangleMesh`` of a mesh (:meth:`TriangleMesh.to_open3d`) or an
    ``open3d.geometry.PointCloud`` of a cloud (:func:`rangekit.surface.cloud.cloud_to_open3d`); anything
    :func:`as_mesh` / :func:`as_cloud` accepts."""
    if isinstance(x, TriangleMesh) or (_library(x) and type(x).__name__ in ("TriangleMesh", "Trimesh", "Scene")):
        return as_mesh(x, "to_open3d(x)").to_open3d()
    return _cloud_to_open3d(as_cloud(x, "to_open3d(x)"))


def as_cloud(x, what: str = "cloud") -> PointCloud:
    """``x`` as a rangekit PointCloud (the object itself when it is one).

    Parameters
    ----------
    x : an (N, 3) array of points (metres) or (N, 6) points and normals, a PointCloud, a mesh (its vertices
        with their area-weighted normals), an
        ``open3d.geometry.PointCloud`` / ``TriangleMesh`` or a ``trimesh.PointCloud`` / ``Trimesh`` (their
        points or vertices, colours and normals carried over where the object has them).
    what : the argument's name in the error message (e.g. ``"icp source"``).

    Raises
    ------
    InputError
        For anything else, naming the type (or the array shape) found (an ArgumentTypeError, also a TypeError,
        for a type that is no cloud).
    """
    check_text("what", what, what="the argument's name")
    if isinstance(x, PointCloud):
        return x
    if isinstance(x, TriangleMesh):
        return PointCloud(x.vertices, x.vertex_colours, vertex_normals(x.vertices, x.triangles, sums=x.normal_sums))
    lib = _library(x)
    if lib:
        if type(x).__name__ in ("TriangleMesh", "Trimesh", "Scene"):
            return as_cloud(as_mesh(x, what), what)
        return from_open3d(x) if lib == "open3d" else from_trimesh(x)
    if isinstance(x, (np.ndarray, list, tuple)):
        try:
            a = np.asarray(x, dtype=np.float64)
        except (TypeError, ValueError):
            a = None
        if a is not None and a.ndim == 2 and a.shape[1] in (3, 6):
            return PointCloud(a[:, :3], normals=a[:, 3:] if a.shape[1] == 6 else None)
        found = f"an array of shape {a.shape}" if a is not None else f"a {type(x).__name__} that is not numeric"
        raise (InputError if a is not None else ArgumentTypeError)(f"{what}: expected {CLOUD_KINDS}, found {found}")
    raise ArgumentTypeError(f"{what}: expected {CLOUD_KINDS}, found {_type_name(x)}")


def as_mesh(x, what: str = "mesh") -> TriangleMesh:
    """``x`` as a rangekit TriangleMesh (the object itself when it is one).

    Parameters
    ----------
    x : a TriangleMesh, a ``(vertices, triangles)`` pair of arrays ((V, 3) metres, (F, 3) indices), an
        ``open3d.geometry.TriangleMesh`` or a ``trimesh.Trimesh`` / ``Scene``.
    what : the argument's name in the error message.

    Raises
    ------
    InputError
        For anything else (a point cloud included: it has no triangles), naming the type found (an
        ArgumentTypeError, also a TypeError).
    """
    check_text("what", what, what="the argument's name")
    if isinstance(x, TriangleMesh):
        return x
    lib = _library(x)
    if lib and type(x).__name__ in ("TriangleMesh", "Trimesh", "Scene"):
        return from_open3d(x) if lib == "open3d" else from_trimesh(x)
    if isinstance(x, tuple) and len(x) == 2:
        return TriangleMesh(np.asarray(x[0], dtype=np.float64), np.asarray(x[1]))
    found = f"an array of shape {np.shape(x)}" if isinstance(x, np.ndarray) else _type_name(x)
    raise ArgumentTypeError(f"{what}: expected {MESH_KINDS}, found {found}")
