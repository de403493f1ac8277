"""PLY files (Stanford polygon format) of point clouds and meshes: one reader and one writer.

Reader (:func:`read_ply`): ASCII and binary of either byte order, any elements (vertices, faces, a
Stanford/Cyberware ``range_grid`` with ragged ``list uchar int vertex_indices``), comments and ``obj_info``
lines; vectorised numpy (a Python loop over rows only for binary lists of varying length, and only to
find row offsets). Malformed and truncated files raise FileFormatError naming the file, the expected
and the found value. Writer (:func:`cloud_ply_bytes`, :func:`mesh_ply_bytes`): binary little-endian.

Why not ``plyfile`` (1.1.5): it reads these files too, but its ASCII path parses row by row in Python:
the Stanford scan bun000.ply (ASCII, ragged range grid) takes 2.5 s against 0.12 s here. On a binary
897k-triangle mesh it memory-maps (0.001 s with ``known_list_len``, 4.3 s without) against 0.011 s here;
and its errors would need wrapping to name the expected and found values.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError
from rangekit.formats.parsing import ascii_rows, read_bytes, truncated_error
from rangekit.surface.cloud import PointCloud
from rangekit.surface.mesh import TriangleMesh

__all__ = ["PlyLists", "PlyHeader", "read_ply", "ply_points", "ply_observed", "ply_vertex_attributes", "ply_vertex_scalar",
           "cloud_ply_bytes",
           "mesh_ply_bytes"]


@dataclass(frozen=True)
class PlyLists:
    """A PLY list property: one variable-length list per row, stored flat."""

    counts: np.ndarray  # (n,) int64 length of each row's list
    items: np.ndarray   # (counts.sum(),) the lists' items, row after row


def _ragged_index(starts: np.ndarray, counts: np.ndarray, step: int = 1) -> np.ndarray:
    """Flat positions ``starts[i] + step * j`` for j < counts[i], row after row."""
    total = int(counts.sum())
    first = np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(starts, counts) + (np.arange(total) - first) * step




_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_END_HEADER = re.compile(rb"^end_header[ \t]*(\r\n|\n|\r)?", re.MULTILINE)


@dataclass(frozen=True)
class _PlyProperty:
    name: str
    dtype: str                      # numpy type without byte order, e.g. "f4"
    count_dtype: str | None = None  # list properties: the type of the length prefix


@dataclass(frozen=True)
class _PlyElement:
    name: str
    count: int
    properties: tuple[_PlyProperty, ...]


@dataclass(frozen=True)
class PlyHeader:
    byte_order: str | None           # None for ASCII, "<" or ">" for binary
    elements: tuple[_PlyElement, ...]
    obj_info: dict[str, str]         # Stanford "obj_info key value" lines
    data_start: int                  # byte offset of the body
    n_lines: int                     # lines in the header

    def element(self, name: str) -> _PlyElement:
        return next(e for e in self.elements if e.name == name)


def _parse_ply_header(path: Path, data: bytes) -> PlyHeader:
    if not re.match(rb"ply[ \t]*(\r\n|\n|\r)", data):
        raise FileFormatError(f"{path}: expected a PLY file starting with the line 'ply', found {data[:16]!r}")
    end = _END_HEADER.search(data)
    if end is None:
        raise FileFormatError(f"{path}: expected a PLY header ending in a line 'end_header', found none")
    lines = data[:end.start()].decode("latin-1").splitlines()
    fmt, elements, obj_info = None, [], {}
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        if not words or words[0] == "comment":
            continue
        try:
            if words[0] == "format":
                if len(words) != 3 or words[1] not in _PLY_FORMATS:
                    raise ValueError(f"'format {{{'|'.join(_PLY_FORMATS)}}} 1.0'")
                fmt = words[1]
            elif words[0] == "obj_info":
                obj_info[words[1] if len(words) > 1 else ""] = " ".join(words[2:])
            elif words[0] == "element":
                if len(words) != 3 or not words[2].isdigit():
                    raise ValueError("'element <name> <count>'")
                elements.append(_PlyElement(words[1], int(words[2]), ()))
            elif words[0] == "property":
                if not elements:
                    raise ValueError("an 'element' line before the first 'property'")
                if len(words) == 3 and words[1] in _PLY_TYPES:
                    prop = _PlyProperty(words[2], _PLY_TYPES[words[1]])
                elif (len(words) == 5 and words[1] == "list" and _PLY_TYPES.get(words[2], "f")[0] in "iu"
                      and words[3] in _PLY_TYPES):
                    prop = _PlyProperty(words[4], _PLY_TYPES[words[3]], _PLY_TYPES[words[2]])
                else:
                    raise ValueError("'property <type> <name>' or 'property list <integer type> <type> "
                                     f"<name>' with types from {', '.join(_PLY_TYPES)}")
                e = elements[-1]
                if prop.name in {p.name for p in e.properties}:
                    raise ValueError(f"one property {prop.name!r} per element")
                elements[-1] = _PlyElement(e.name, e.count, e.properties + (prop,))
            else:
                raise ValueError("'format', 'comment', 'obj_info', 'element' or 'property'")
        except ValueError as exc:
            raise FileFormatError(f"{path}: PLY header line {number}: expected {exc}, found {line!r}") from None
    if fmt is None:
        raise FileFormatError(f"{path}: expected a 'format' line in the PLY header, found none")
    return PlyHeader(_PLY_FORMATS[fmt], tuple(elements), obj_info, end.end(), len(lines) + 1)


def read_ply(path: Path, wanted: tuple[str, ...]) -> tuple[PlyHeader, dict[str, dict]]:
    """Header and the ``wanted`` elements (property name -> (n,) array or PlyLists) of a PLY file.

    Elements before the last wanted one are parsed and skipped; those after it are not read.
    """
    data = read_bytes(path)
    header = _parse_ply_header(path, data)
    names = [e.name for e in header.elements]
    for name in wanted:
        if name not in names:
            raise FileFormatError(f"{path}: expected a PLY element {name!r}, found elements {names}")
    elements = header.elements[:max(names.index(name) for name in wanted) + 1]
    out = {}
    if header.byte_order is None:
        n_rows = sum(e.count for e in elements)
        values, counts, lines = ascii_rows(path, data, header.data_start, n_rows, header.n_lines + 1)
        row = start = 0
        for e in elements:
            if len(counts) < row + e.count:
                raise truncated_error(path, e.name, e.count, len(counts) - row)
            rows = slice(row, row + e.count)
            out[e.name] = _splitascii_rows(path, e, values, counts[rows], lines[rows], start)
            start += int(counts[rows].sum())
            row += e.count
    else:
        offset = header.data_start
        for e in elements:
            out[e.name], offset = _read_binary_element(path, data, offset, e, header.byte_order)
    return header, {name: out[name] for name in wanted}


def _splitascii_rows(path: Path, e: _PlyElement, values: np.ndarray, counts: np.ndarray,
                      lines: np.ndarray, start: int) -> dict:
    """The properties of element ``e`` from its rows of numbers (one row per line), vectorised."""
    row_start = start + np.cumsum(counts) - counts
    row_end = row_start + counts
    pos = row_start.copy()
    out = {}

    def check(bad: np.ndarray, expected: str) -> None:
        if bad.any():
            k = int(np.argmax(bad))
            raise FileFormatError(f"{path}: line {lines[k]}: expected {expected} for element {e.name!r}, "
                                  f"found {counts[k]} numbers")

    for p in e.properties:
        check(pos >= row_end, f"a value for property {p.name!r}")
        if p.count_dtype is None:
            out[p.name] = values[pos]
            pos += 1
        else:
            n = values[pos]
            check((n != np.floor(n)) | (n < 0), f"a list length (a whole number >= 0) for {p.name!r}")
            n = n.astype(np.int64)
            check(pos + 1 + n > row_end, f"{p.name!r} to hold as many items as its length")
            out[p.name] = PlyLists(n, values[_ragged_index(pos + 1, n)])
            pos += 1 + n
    check(pos != row_end, f"{len(e.properties)} properties")
    return out


def _read_binary_element(path: Path, data: bytes, offset: int, e: _PlyElement, bo: str
                         ) -> tuple[dict, int]:
    """Element ``e`` starting at byte ``offset``: (property name -> array or PlyLists, offset after it)."""
    if not e.properties or e.count == 0:
        empty = {p.name: np.empty(0, p.dtype) if p.count_dtype is None
                 else PlyLists(np.empty(0, np.int64), np.empty(0, p.dtype)) for p in e.properties}
        return empty, offset
    available = len(data) - offset
    if all(p.count_dtype is None for p in e.properties):
        dt = np.dtype([(p.name, bo + p.dtype) for p in e.properties])
        if available < e.count * dt.itemsize:
            raise truncated_error(path, e.name, e.count, max(available, 0) // dt.itemsize)
        rec = np.frombuffer(data, dtype=dt, count=e.count, offset=offset)
        return {p.name: rec[p.name] for p in e.properties}, offset + e.count * dt.itemsize

    # Fast path: every row's lists are as long as the first row's (a triangle mesh, say).
    first, _ = _walk_binary_rows(path, data, offset, e, bo, 1)
    u8 = np.frombuffer(data, dtype=np.uint8)
    lengths = [int(_gather(u8, first[:, j], bo + p.count_dtype)[0]) if p.count_dtype else 0
               for j, p in enumerate(e.properties)]
    fields = []
    for j, (p, k) in enumerate(zip(e.properties, lengths)):
        if p.count_dtype is None:
            fields.append((f"v{j}", bo + p.dtype))
        else:
            fields.append((f"n{j}", bo + p.count_dtype))
            if k > 0:
                fields.append((f"v{j}", bo + p.dtype, (k,)))
    dt = np.dtype(fields)
    if available >= e.count * dt.itemsize:
        rec = np.frombuffer(data, dtype=dt, count=e.count, offset=offset)
        if all(p.count_dtype is None or np.all(rec[f"n{j}"] == k)
               for j, (p, k) in enumerate(zip(e.properties, lengths))):
            out = {}
            for j, (p, k) in enumerate(zip(e.properties, lengths)):
                if p.count_dtype is None:
                    out[p.name] = rec[f"v{j}"]
                else:
                    items = rec[f"v{j}"].reshape(-1) if k > 0 else np.empty(0, bo + p.dtype)
                    out[p.name] = PlyLists(np.full(e.count, k, dtype=np.int64), items)
            return out, offset + e.count * dt.itemsize

    # General path: lists of varying length. Walk the rows for their offsets, then gather vectorised.
    offsets, end = _walk_binary_rows(path, data, offset, e, bo, e.count)
    out = {}
    for j, p in enumerate(e.properties):
        if p.count_dtype is None:
            out[p.name] = _gather(u8, offsets[:, j], bo + p.dtype)
        else:
            n = _gather(u8, offsets[:, j], bo + p.count_dtype).astype(np.int64)
            size = np.dtype(p.dtype).itemsize
            starts = offsets[:, j] + np.dtype(p.count_dtype).itemsize
            out[p.name] = PlyLists(n, _gather(u8, _ragged_index(starts, n, size), bo + p.dtype))
    return out, end


def _walk_binary_rows(path: Path, data: bytes, offset: int, e: _PlyElement, bo: str, n_rows: int
                      ) -> tuple[np.ndarray, int]:
    """Byte offset of each property in each of the first ``n_rows`` rows, and the offset after them.

    A Python loop over rows: only used when list lengths vary from row to row, where the position of
    a row depends on every list before it.
    """
    steps = [(np.dtype(p.dtype).itemsize, None, 0) if p.count_dtype is None else
             (np.dtype(p.count_dtype).itemsize, struct.Struct(bo + np.dtype(p.count_dtype).char),
              np.dtype(p.dtype).itemsize) for p in e.properties]
    end = len(data)
    offsets = []
    pos = offset
    for row in range(n_rows):
        for size, length, item_size in steps:
            offsets.append(pos)
            if length is not None:
                if pos + size > end:
                    raise truncated_error(path, e.name, e.count, row)
                n = length.unpack_from(data, pos)[0]
                if n < 0:
                    raise FileFormatError(f"{path}: {e.name!r} row {row}: expected a list length >= 0, found {n}")
                pos += n * item_size
            pos += size
        if pos > end:
            raise truncated_error(path, e.name, e.count, row)
    return np.array(offsets, dtype=np.int64).reshape(n_rows, len(steps)), pos


def _gather(u8: np.ndarray, offsets: np.ndarray, dtype: str) -> np.ndarray:
    """Values of ``dtype`` at byte ``offsets`` of the uint8 buffer ``u8`` (vectorised)."""
    dt = np.dtype(dtype)
    return u8[offsets[:, None] + np.arange(dt.itemsize)].view(dt).reshape(-1)


def ply_points(path: Path, header: PlyHeader, vertex: dict) -> np.ndarray:
    props = {p.name: p for p in header.element("vertex").properties}
    if not all(c in props and props[c].count_dtype is None for c in "xyz"):
        found = ", ".join(n + (" (a list)" if p.count_dtype else "") for n, p in props.items())
        raise FileFormatError(f"{path}: expected vertex properties x, y, z (one number each), found {found or 'none'}")
    return np.column_stack([np.asarray(vertex[c], dtype=np.float64) for c in "xyz"])


def ply_observed(header: PlyHeader, vertex: dict) -> np.ndarray | None:
    """(N,) bool of a PLY vertex element's ``observed`` property (non-zero = observed), or None without it."""
    props = {p.name: p for p in header.element("vertex").properties}
    if "observed" not in props or props["observed"].count_dtype is not None:
        return None
    return np.asarray(vertex["observed"]) != 0


def ply_vertex_attributes(path: Path, header: PlyHeader, vertex: dict
                          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(points (N, 3) float64, normals (N, 3) float64 or None, colours (N, 3) float64 in [0, 1] or None)
    of a PLY vertex element: ``x y z``, ``nx ny nz``, ``red green blue`` or ``diffuse_*`` (integer
    colours span their type's range, float ones are in [0, 1])."""
    props = {p.name: p for p in header.element("vertex").properties}

    def columns(names: tuple[str, ...]) -> np.ndarray | None:
        if all(n in props and props[n].count_dtype is None for n in names):
            return np.column_stack([np.asarray(vertex[n], dtype=np.float64) for n in names])
        return None

    normals = columns(("nx", "ny", "nz"))
    colours = None
    for names in (("red", "green", "blue"), ("diffuse_red", "diffuse_green", "diffuse_blue")):
        colours = columns(names)
        if colours is not None:
            dtype = np.dtype(props[names[0]].dtype)
            if dtype.kind in "iu":  # integer colours span the type's range; float ones are in [0, 1]
                colours = colours / np.iinfo(dtype).max
            break
    return ply_points(path, header, vertex), normals, colours


def ply_vertex_scalar(header: PlyHeader, vertex: dict, name: str) -> np.ndarray | None:
    """(N,) float64 values of the scalar vertex property ``name`` (e.g. ``sigma``), or None if absent."""
    props = {p.name: p for p in header.element("vertex").properties}
    if name in props and props[name].count_dtype is None:
        return np.asarray(vertex[name], dtype=np.float64)
    return None


# ----------------------------------------------------------------------------------------- writer

_PLY_NAMES = {"float64": "double", "float32": "float", "uint8": "uchar", "int32": "int"}


def _ply_bytes(comment: str, vertex: np.ndarray, faces: np.ndarray | None = None) -> bytes:
    """Binary little-endian PLY of a structured vertex array and optional (F, 3) int32 triangles (the
    header and the records joined in one copy: a 2M-point cloud's body is 86 MB)."""
    header = ["ply", "format binary_little_endian 1.0", f"comment {comment}", f"element vertex {len(vertex)}"]
    header += [f"property {_PLY_NAMES[vertex.dtype[n].name]} {n}" for n in vertex.dtype.names]
    parts = [memoryview(vertex).cast("B")]
    if faces is not None:
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        rec["n"] = 3
        rec["idx"] = faces
        header += [f"element face {len(rec)}", "property list uchar int vertex_indices"]
        parts.append(memoryview(rec).cast("B"))
    header.append("end_header")
    return b"".join([("\n".join(header) + "\n").encode("ascii"), *parts])


def _vertex_records(points: np.ndarray, normals: np.ndarray | None, colours: np.ndarray | None,
                    sigma: np.ndarray | None = None, observed: np.ndarray | None = None) -> np.ndarray:
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
    rec = np.empty(len(points), dtype=fields)
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


def cloud_ply_bytes(cloud: PointCloud) -> bytes:
    """A point cloud as binary PLY: float64 xyz, float32 normals, uint8 RGB, float32 ``sigma`` (the
    predicted std along the camera ray, metres), comment "metres"."""
    return _ply_bytes("rangekit point cloud, metres",
                      _vertex_records(cloud.points, cloud.normals, cloud.colours, cloud.sigma))


def mesh_ply_bytes(mesh: TriangleMesh) -> bytes:
    """A triangle mesh as binary PLY: float64 xyz, uint8 RGB, uint8 ``observed`` (when the mesh has the flag),
    faces as ``list uchar int``, comment "metres"."""
    return _ply_bytes("rangekit mesh, metres", _vertex_records(mesh.vertices, None, mesh.vertex_colours,
                                                               observed=mesh.observed), mesh.triangles)
