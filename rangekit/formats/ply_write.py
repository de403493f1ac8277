"""PLY files of point clouds and meshes: the one writer (the reader is :mod:`rangekit.formats.ply`).

Binary little-endian from one structured array per element (plyfile writes list properties row by row in
Python: 1.4 CPU-s for 897k triangles, against 0.02); a cloud's records go to the file a chunk at a time
(:func:`write_cloud_ply`).
"""

from __future__ import annotations

import io
from typing import BinaryIO

import numpy as np

from rangekit.errors import InputError
from rangekit.surface.cloud import PointCloud
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.quality import vertex_normals

__all__ = ["cloud_ply_bytes", "mesh_ply_bytes", "write_cloud_ply"]


_PLY_NAMES = {"float64": "double", "float32": "float", "uint8": "uchar", "int32": "int", "uint16": "ushort",
              "int16": "short", "uint32": "uint"}


def _ply_header(comment: str, vertex: np.dtype, n_vertex: int, n_faces: int | None = None) -> bytes:
    """The header of a binary little-endian PLY of ``n_vertex`` structured ``vertex`` rows and, when given,
    ``n_faces`` triangles (``list uchar int``)."""
    header = ["ply", "format binary_little_endian 1.0", f"comment {comment}", f"element vertex {n_vertex}"]
    header += [f"property {_PLY_NAMES[vertex[n].name]} {n}" for n in vertex.names]
    if n_faces is not None:
        header += [f"element face {n_faces}", "property list uchar int vertex_indices"]
    return ("\n".join(header + ["end_header"]) + "\n").encode("ascii")


def _ply_bytes(comment: str, vertex: np.ndarray, faces: np.ndarray | None = None) -> bytes:
    """Binary little-endian PLY of a structured vertex array and optional (F, 3) int32 triangles (the
    header and the records joined in one copy)."""
    parts = [memoryview(vertex).cast("B")]
    if faces is not None:
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        rec["n"] = 3
        rec["idx"] = faces
        parts.append(memoryview(rec).cast("B"))
    return b"".join([_ply_header(comment, vertex.dtype, len(vertex), None if faces is None else len(faces)), *parts])


def _vertex_records(points: np.ndarray, normals: np.ndarray | None, colours: np.ndarray | None,
                    sigma: np.ndarray | None = None, observed: np.ndarray | None = None,
                    extra: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Structured vertex rows: float64 x y z, float32 nx ny nz, uint8 red green blue, float32 sigma
    (metres), uint8 observed (1 where a view's points support the vertex, 0 where the fusion invented it)
    (the optional ones only when given; colours in [0, 1] are rounded to 8 bits)."""
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if colours is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if sigma is not None:
        fields += [("sigma", "<f4")]
    if observed is not None:
        fields += [("observed", "u1")]
    extra = extra or {}
    taken = {f[0] for f in fields} & set(extra)
    if taken:
        raise InputError(f"PLY fields {sorted(taken)}: expected names other than the vertex's own, found them again")
    fields += [(name, "<" + values.dtype.str[1:]) for name, values in extra.items()]
    rec = np.empty(len(points), dtype=fields)
    for name, values in extra.items():
        rec[name] = values
    rec["x"], rec["y"], rec["z"] = points.T
    if normals is not None:
        rec["nx"], rec["ny"], rec["nz"] = normals.T
    if colours is not None:
        rgb = np.clip(np.rint(colours * 255), 0, 255).astype(np.uint8)
        rec["red"], rec["green"], rec["blue"] = rgb.T
    if sigma is not None:
        rec["sigma"] = sigma
    if observed is not None:
        rec["observed"] = np.asarray(observed, dtype=bool)
    return rec


def cloud_ply_bytes(cloud: PointCloud, fields: dict[str, np.ndarray] | None = None) -> bytes:
    """A point cloud as binary PLY (:func:`write_cloud_ply`'s bytes)."""
    out = io.BytesIO()
    write_cloud_ply(out, cloud, fields)
    return out.getvalue()


def write_cloud_ply(f: BinaryIO, cloud: PointCloud, fields: dict[str, np.ndarray] | None = None,
                    chunk: int = 1 << 18) -> None:
    """Write a point cloud to the binary file ``f`` as binary PLY: float64 xyz, float32 normals, uint8 RGB,
    float32 ``sigma`` (the predicted std along the camera ray, metres), then ``fields``: extra per-point
    properties, name -> (N,) array of its own type (e.g. ``view`` uint16: the view each point of a merged
    cloud came from); comment "metres". The records go out ``chunk`` points at a time: a 2M-point merged
    cloud's 86 MB body is never whole in memory."""
    fields = {name: np.asarray(values) for name, values in (fields or {}).items()}
    for name, values in fields.items():
        if values.shape != (len(cloud),) or values.dtype.name not in _PLY_NAMES:
            raise InputError(f"PLY field {name!r}: expected a ({len(cloud)},) array of {', '.join(_PLY_NAMES)}, "
                             f"found {values.dtype} {values.shape}")

    def records(s: slice) -> np.ndarray:
        return _vertex_records(cloud.points[s], *(None if a is None else a[s] for a in
                                                  (cloud.normals, cloud.colours, cloud.sigma)),
                               extra={name: values[s] for name, values in fields.items()})

    f.write(_ply_header("rangekit point cloud, metres", records(slice(0, 0)).dtype, len(cloud)))
    for start in range(0, len(cloud), chunk):
        f.write(memoryview(records(slice(start, start + chunk))).cast("B"))


def mesh_ply_bytes(mesh: TriangleMesh, units: str = "metres") -> bytes:
    """A triangle mesh as binary PLY: float64 xyz, float32 unit area-weighted vertex normals ``nx ny nz`` (what
    MeshLab, Open3D and trimesh shade with), uint8 RGB, uint8 ``observed`` and ``carved`` (when the mesh has
    the flags: observed 1 where a view's points support the vertex; carved 1 where an unobserved vertex lies on the
    hull free-space carving left, rangekit.surface.carve; both 0: a fitted guess), faces
    as ``list uchar int``, comment "rangekit mesh, UNITS" (``units``: metres, or pixels for a photometric
    surface whose camera is not known)."""
    normals = vertex_normals(mesh.vertices, mesh.triangles, sums=mesh.normal_sums)
    carved = None if mesh.carved is None else {"carved": np.asarray(mesh.carved, dtype=np.uint8)}
    return _ply_bytes(f"rangekit mesh, {units}", _vertex_records(mesh.vertices, normals, mesh.vertex_colours,
                                                               observed=mesh.observed, extra=carved), mesh.triangles)
