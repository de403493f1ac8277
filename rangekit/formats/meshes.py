"""Mesh files, chosen by extension: ``.ply`` (read and written by :mod:`rangekit.formats.ply`, with vertex
normals), ``.obj``, ``.stl`` and ``.glb`` (binary glTF 2.0: float32 vertices) via trimesh, ``.off`` (read
only, via trimesh). Writes are atomic."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit._runtime.arguments import check_path, check_text
from rangekit.regular_files import check_regular_file, read_regular_file
from rangekit.errors import FileFormatError
from rangekit.formats.ply import ply_flag, ply_observed, ply_vertex_attributes, read_ply
from rangekit.formats.ply_write import mesh_ply_bytes
from rangekit.io import atomic_write_bytes
from rangekit.surface.convert import as_mesh
from rangekit.surface.mesh import TriangleMesh

__all__ = ["save_mesh", "load_mesh", "MESH_FORMATS"]


def _write_via_trimesh(file_type: str, **options):
    def write(mesh: TriangleMesh) -> bytes:
        data = mesh.to_trimesh().export(file_type=file_type, **options)
        return data.encode("utf-8") if isinstance(data, str) else bytes(data)
    return write


# OBJ: 12 decimals (1e-12 m; trimesh's default 8 rounds to 1e-8 m).
MESH_FORMATS = {".ply": mesh_ply_bytes, ".obj": _write_via_trimesh("obj", digits=12), ".stl": _write_via_trimesh("stl"),
                ".glb": _write_via_trimesh("glb")}
_READ_ONLY = (".off",)  # read by trimesh, never written


def _check_suffix(path: Path, known=MESH_FORMATS) -> str:
    suffix = path.suffix.lower()
    if suffix not in known:
        raise FileFormatError(f"{path}: unknown mesh format {path.suffix!r}; known: {', '.join(known)}")
    return suffix


def save_mesh(path: str | Path, mesh, *, units: str = "metres") -> None:
    """Write ``mesh`` (any mesh :func:`rangekit.surface.convert.as_mesh` takes: TriangleMesh, Open3D, trimesh)
    in the format given by the extension (``.ply`` binary with vertex normals and colours, ``.obj``, ``.stl``,
    ``.glb``).

    ``units`` names the coordinates' unit in a PLY's comment. The write is atomic (temporary file + rename). STL keeps no colours; OBJ and GLB keep them as vertex
    colours.
    """
    path = Path(check_path("path", path, what="a mesh file"))
    check_text("units", units, what="the coordinates' unit")
    suffix = _check_suffix(path)
    mesh = as_mesh(mesh, "save_mesh mesh")
    atomic_write_bytes(path, mesh_ply_bytes(mesh, units) if suffix == ".ply" else MESH_FORMATS[suffix](mesh))


def _read_ply_mesh(path: Path) -> TriangleMesh:
    """A PLY mesh: vertices (and colours) in file order, polygons split into fans of triangles."""
    header, elements = read_ply(path, ("vertex", "face"))
    points, _, colours = ply_vertex_attributes(path, header, elements["vertex"])
    face = elements["face"]
    lists = face.get("vertex_indices", face.get("vertex_index"))
    if lists is None or not hasattr(lists, "counts"):
        raise FileFormatError(f"{path}: expected a face list property 'vertex_indices', found "
                              f"{', '.join(face) or 'none'}")
    declared = {p.name: p.dtype for p in header.element("face").properties}
    declared = declared.get("vertex_indices", declared.get("vertex_index"))
    if np.dtype(declared).kind not in "iu" or not np.all(lists.items == np.floor(lists.items)):
        raise FileFormatError(f"{path}: expected whole-number vertex indices in the face lists, found "
                              f"{'type ' + np.dtype(declared).name if np.dtype(declared).kind not in 'iu' else 'fractions'}")
    items = lists.items.astype(np.int64)
    if np.all(lists.counts == 3):
        triangles = items.reshape(-1, 3)
    else:  # polygons: fans (v0, v_k, v_k+1)
        n_tri = np.maximum(lists.counts - 2, 0)
        first = np.repeat(np.cumsum(lists.counts) - lists.counts, n_tri)
        j = np.arange(int(n_tri.sum())) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
        triangles = np.column_stack([items[first], items[first + j + 1], items[first + j + 2]])
    if len(triangles) == 0:
        raise FileFormatError(f"{path}: expected a triangle mesh, found no triangles")
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise FileFormatError(f"{path}: expected face indices in [0, {len(points)}), found "
                              f"[{triangles.min()}, {triangles.max()}]")
    if not np.all(np.isfinite(points)):
        raise FileFormatError(f"{path}: expected finite vertices, found "
                              f"{np.count_nonzero(~np.isfinite(points).all(axis=1))} that are not")
    return TriangleMesh(points, triangles, None if colours is None else colours.astype(np.float32),
                        ply_observed(header, elements["vertex"]), ply_flag(header, elements["vertex"], "carved"))


def _obj_geometry(path: Path):
    """An OBJ's text without its texture coordinates and materials (``vt``, ``mtllib``, ``usemtl`` lines; face
    corners ``v/vt/vn`` become ``v//vn``), as a file object for trimesh."""
    import io
    import re

    keep = []
    for line in read_regular_file(path, what="an OBJ mesh").splitlines():
        word = line.split(maxsplit=1)[0] if line.strip() else b""
        if word in (b"vt", b"mtllib", b"usemtl"):
            continue
        if word == b"f":
            line = re.sub(rb"(-?\d+)/-?\d*(/-?\d*)?", lambda m: m.group(1) + (b"/" + m.group(2) if m.group(2) and
                                                                              len(m.group(2)) > 1 else b""), line)
        keep.append(line)
    return io.BytesIO(b"\n".join(keep))


def load_mesh(path: str | Path) -> TriangleMesh:
    """Read a ``.ply`` (:mod:`rangekit.formats.ply`), ``.obj``, ``.stl``, ``.off`` or ``.glb`` (trimesh; a glTF
    scene's meshes concatenated in the scene frame) mesh; vertex order kept, nothing merged.

    Raises
    ------
    FileFormatError
        If the file is missing, a folder, has an unknown extension, is malformed, holds no triangles or
        a vertex that is not finite.
    """
    path = Path(check_path("path", path, what="a mesh file"))
    suffix = _check_suffix(path, (*MESH_FORMATS, *_READ_ONLY))
    if path.is_dir():
        raise FileFormatError(f"{path}: is a folder, expected a mesh file")
    check_regular_file(path, what="a mesh file")
    if suffix == ".ply":
        return _read_ply_mesh(path)
    import trimesh

    try:
        try:
            loaded = trimesh.load_mesh(path, file_type=suffix[1:], process=False)
        except ModuleNotFoundError as exc:
            # Texture coordinates make trimesh build a texture, which needs Pillow (not a dependency): the
            # geometry is read without them.
            if suffix != ".obj" or "PIL" not in str(exc):
                raise
            loaded = trimesh.load_mesh(_obj_geometry(path), file_type="obj", process=False)
    except Exception as exc:  # trimesh raises many types for a corrupt file
        raise FileFormatError(f"{path}: cannot read {suffix[1:].upper()} mesh: {exc}") from exc
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_mesh()
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise FileFormatError(f"{path}: expected a triangle mesh, found no triangles")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        raise FileFormatError(f"{path}: expected finite vertices, found "
                              f"{np.count_nonzero(~np.isfinite(vertices).all(axis=1))} that are not")
    colours = None
    if loaded.visual.kind == "vertex":
        colours = np.asarray(loaded.visual.vertex_colors)[:, :3].astype(np.float32) / 255.0
    return TriangleMesh(vertices, np.asarray(loaded.faces, dtype=np.int64), colours)
