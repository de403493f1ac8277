"""PLY files (Stanford polygon format) of point clouds and meshes: the one reader.

Reader (:func:`read_ply`): the header is parsed here (its errors name the line, the expected and the found
text); binary bodies of either byte order are read by ``plyfile`` (memory-mapped: each list property's
length taken from the element's first row, plyfile's own row-by-row reader when lengths vary); ASCII
bodies by a vectorised numpy parser, because plyfile parses ASCII row by row in Python (the Stanford scan
bun000.ply, ASCII with a ragged ``range_grid``: 0.05 s here against 1.6 s, docs/benchmarks.md). Malformed
and truncated files raise FileFormatError naming the file, the expected and the found value. The writer
is :mod:`rangekit.formats.ply_write`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError, shown
from rangekit.formats.parsing import ascii_rows, read_bytes, truncated_error

__all__ = ["PlyLists", "PlyHeader", "read_ply", "ply_points", "ply_observed", "ply_flag", "ply_vertex_attributes", "ply_vertex_scalar"]


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
                if words[1] in {e.name for e in elements}:
                    raise ValueError(f"one element {words[1]!r} per file")
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
            raise FileFormatError(f"{path}: PLY header line {number}: expected {exc}, found {shown(line)}") from None
    if fmt is None:
        raise FileFormatError(f"{path}: expected a 'format' line in the PLY header, found none")
    return PlyHeader(_PLY_FORMATS[fmt], tuple(elements), obj_info, end.end(), len(lines) + 1)


def _read_head(path: Path) -> bytes:
    """The file's first bytes, at least up to the line 'end_header' (or the whole file when it has none)."""
    try:
        with open(path, "rb") as f:
            head = b""
            while True:
                chunk = f.read(1 << 16)
                head += chunk
                if not chunk or _END_HEADER.search(head) or len(head) > (1 << 24):
                    return head
    except FileNotFoundError as exc:
        raise FileFormatError(f"{path}: point cloud file not found") from exc
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read point cloud file: {exc.strerror or exc}") from exc


def read_ply(path: Path, wanted: tuple[str, ...]) -> tuple[PlyHeader, dict[str, dict]]:
    """Header and the ``wanted`` elements (property name -> (n,) array or PlyLists) of a PLY file.

    ASCII: elements before the last wanted one are parsed and skipped, those after it are not read.
    Binary: read by plyfile (see the module's docstring).
    """
    head = _read_head(path)
    header = _parse_ply_header(path, head)
    names = [e.name for e in header.elements]
    for name in wanted:
        if name not in names:
            raise FileFormatError(f"{path}: expected a PLY element {name!r}, found elements {names}")
    if header.byte_order is not None:
        return header, _read_binary(path, header, wanted)
    data = read_bytes(path)
    elements = header.elements[:max(names.index(name) for name in wanted) + 1]
    out = {}
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


def _first_row_list_lengths(path: Path, header: PlyHeader) -> dict[str, dict[str, int]]:
    """plyfile's ``known_list_len``: each list property's length in its element's first row, found while
    the elements before it have fixed-size rows (a vertex element before the faces); later ones are left
    to plyfile's row-by-row reader."""
    known, offset, bo = {}, header.data_start, header.byte_order
    with open(path, "rb") as f:
        for e in header.elements:
            lengths, row_size = {}, 0
            f.seek(offset)
            for p in e.properties:
                if p.count_dtype is None:
                    row_size += np.dtype(p.dtype).itemsize
                    f.seek(np.dtype(p.dtype).itemsize, 1)
                    continue
                size = np.dtype(p.count_dtype).itemsize
                raw = f.read(size)
                if len(raw) < size or e.count == 0:
                    return known
                n = int(np.frombuffer(raw, bo + p.count_dtype)[0])
                lengths[p.name] = n
                row_size += size + n * np.dtype(p.dtype).itemsize
                f.seek(n * np.dtype(p.dtype).itemsize, 1)
            if lengths:
                known[e.name] = lengths
            offset += e.count * row_size
    return known


def _check_body_size(path: Path, header: PlyHeader) -> None:
    """The body must hold at least the bytes the header's counts need (rows of fixed properties, each list
    its length prefix at least): a header declaring 3e8 faces over a few bytes is refused here, before
    plyfile allocates gigabytes for it."""
    import os

    have = os.path.getsize(path) - header.data_start
    used = 0
    for e in header.elements:
        row = 0
        for p in e.properties:
            if p.count_dtype is None:
                row += np.dtype(p.dtype).itemsize
            else:   # a list's length prefix: its items may be 0 in rows after the first (a range grid's 0 or 1)
                row += np.dtype(p.count_dtype).itemsize
        if row and used + e.count * row > have:
            raise truncated_error(path, e.name, e.count, max(have - used, 0) // row)
        used += e.count * row


def _read_binary(path: Path, header: PlyHeader, wanted: tuple[str, ...]) -> dict[str, dict]:
    """The ``wanted`` elements of a binary PLY, read by plyfile (memory-mapped when every list of an element
    is as long as in its first row)."""
    import plyfile

    known = _first_row_list_lengths(path, header)
    _check_body_size(path, header)
    try:
        try:
            ply = plyfile.PlyData.read(str(path), mmap="c", known_list_len=known)
        except plyfile.PlyElementParseError:
            if not known:
                raise
            ply = plyfile.PlyData.read(str(path), mmap=False)   # ragged lists: plyfile's row-by-row reader
    except plyfile.PlyElementParseError as exc:
        if exc.message == "early end-of-file":
            raise truncated_error(path, exc.element.name, exc.element.count, exc.row or 0) from None
        raise FileFormatError(f"{path}: PLY element {exc.element.name!r} row {exc.row}: expected "
                              f"{len(exc.element.properties)} properties, found {exc.message}") from None
    except (plyfile.PlyParseError, ValueError) as exc:
        why = "a list of negative length" if "smaller then zero" in str(exc) else str(exc)   # numpy's words
        raise FileFormatError(f"{path}: expected a readable binary PLY body (list lengths >= 0), found {why}") from None
    out = {}
    for name in wanted:
        e, data = header.element(name), ply[name].data
        out[name] = {}
        for p in e.properties:
            col = data[p.name]
            if p.count_dtype is None:
                out[name][p.name] = col   # a view of the mapped file: the readers copy what they keep
            elif col.dtype != object:  # memory-mapped: (n, k)
                out[name][p.name] = PlyLists(np.full(len(col), col.shape[1] if col.ndim == 2 else 0, np.int64),
                                             np.array(col).reshape(-1))
            else:
                counts = np.fromiter((len(r) for r in col), np.int64, len(col))
                items = np.concatenate(list(col)) if len(col) else np.empty(0, p.dtype)
                out[name][p.name] = PlyLists(counts, items.astype(p.dtype, copy=False))
    return out


def ply_points(path: Path, header: PlyHeader, vertex: dict) -> np.ndarray:
    props = {p.name: p for p in header.element("vertex").properties}
    if not all(c in props and props[c].count_dtype is None for c in "xyz"):
        found = ", ".join(n + (" (a list)" if p.count_dtype else "") for n, p in props.items())
        raise FileFormatError(f"{path}: expected vertex properties x, y, z (one number each), found {found or 'none'}")
    return np.column_stack([np.asarray(vertex[c], dtype=np.float64) for c in "xyz"])


def ply_flag(header: PlyHeader, vertex: dict, name: str) -> np.ndarray | None:
    """(N,) bool of a PLY vertex element's scalar property ``name`` (non-zero = True), or None without it."""
    props = {p.name: p for p in header.element("vertex").properties}
    if name not in props or props[name].count_dtype is not None:
        return None
    return np.asarray(vertex[name]) != 0


def ply_observed(header: PlyHeader, vertex: dict) -> np.ndarray | None:
    """(N,) bool of a PLY vertex element's ``observed`` property (non-zero = observed), or None without it."""
    return ply_flag(header, vertex, "observed")


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
