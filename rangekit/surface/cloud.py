"""Point clouds with colours and normals, and their files (chosen by extension).

Writers (:data:`CLOUD_WRITERS`, :func:`save_cloud`): ``.ply`` (binary little-endian, float64 xyz, float32
normals, uint8 RGB; written with numpy, no open3d needed), ``.xyz`` (text ``x y z [nx ny nz]``), ``.npy``
((N, 3), (N, 6) points + normals or (N, 9) points + normals + colours). Writes are atomic.

Readers (:data:`CLOUD_READERS`, :func:`load_cloud`): ``.ply`` (ASCII and binary of either byte order;
extra elements such as faces or a Stanford ``range_grid`` are skipped), ``.pcd`` (PCL, ASCII and binary),
``.xyz`` / ``.txt`` and ``.npy``. Rows whose point is not finite are dropped. :func:`load_range_grid`
reads a Stanford/Cyberware range-grid PLY as an organised scan. All parsing is vectorised numpy.

Conversion to open3d / trimesh objects happens in :func:`to_open3d` only.
"""

from __future__ import annotations

import io
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from rangekit.errors import FileFormatError, InputError
from rangekit.io import atomic_write_bytes

__all__ = ["PointCloud", "save_cloud", "CLOUD_WRITERS", "load_cloud", "CLOUD_READERS", "RangeGrid",
           "load_range_grid", "to_open3d"]


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points in metres with optional per-point colour and unit normal."""

    points: np.ndarray                 # (N, 3) float64 metres
    colours: np.ndarray | None = None  # (N, 3) float32 linear RGB in [0, 1]
    normals: np.ndarray | None = None  # (N, 3) float64 unit vectors

    def __post_init__(self) -> None:
        P = np.asarray(self.points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3:
            raise InputError(f"PointCloud: points must be (N, 3), found {P.shape}")
        object.__setattr__(self, "points", P)
        for name in ("colours", "normals"):
            a = getattr(self, name)
            if a is not None:
                a = np.asarray(a, dtype=np.float32 if name == "colours" else np.float64)
                if a.shape != P.shape:
                    raise InputError(f"PointCloud: {name} must be {P.shape}, found {a.shape}")
                object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        extra = [n for n in ("colours", "normals") if getattr(self, n) is not None]
        return f"PointCloud({len(self)} points{', ' + ', '.join(extra) if extra else ''})"


def _write_ply(cloud: PointCloud) -> bytes:
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if cloud.normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if cloud.colours is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rec = np.empty(len(cloud), dtype=fields)
    rec["x"], rec["y"], rec["z"] = cloud.points.T
    if cloud.normals is not None:
        rec["nx"], rec["ny"], rec["nz"] = cloud.normals.T
    if cloud.colours is not None:
        rgb = np.clip(np.rint(cloud.colours * 255), 0, 255).astype(np.uint8)
        rec["red"], rec["green"], rec["blue"] = rgb.T
    ply_types = {"<f8": "double", "<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment rangekit point cloud, metres",
              f"element vertex {len(cloud)}"]
    header += [f"property {ply_types[t]} {n}" for n, t in fields]
    header.append("end_header")
    return ("\n".join(header) + "\n").encode("ascii") + rec.tobytes()


def _write_xyz(cloud: PointCloud) -> bytes:
    cols = [cloud.points] + ([cloud.normals] if cloud.normals is not None else [])
    buf = io.StringIO()
    np.savetxt(buf, np.hstack(cols), fmt="%.9g")
    return buf.getvalue().encode("ascii")


def _write_npy(cloud: PointCloud) -> bytes:
    # Columns: points, normals, colours. Colours without normals get NaN normal columns, so that an
    # (N, 6) file always means points + normals.
    normals = cloud.normals
    if normals is None and cloud.colours is not None:
        normals = np.full_like(cloud.points, np.nan)
    cols = [cloud.points] + [a for a in (normals, cloud.colours) if a is not None]
    buf = io.BytesIO()
    np.save(buf, np.hstack(cols))
    return buf.getvalue()


CLOUD_WRITERS = {".ply": _write_ply, ".xyz": _write_xyz, ".npy": _write_npy}


def save_cloud(path: str | Path, cloud: PointCloud) -> None:
    """Write ``cloud`` in the format given by the file extension, atomically."""
    path = Path(path)
    writer = CLOUD_WRITERS.get(path.suffix.lower())
    if writer is None:
        raise FileFormatError(f"{path}: unknown point cloud format {path.suffix!r}; known: "
                              f"{', '.join(CLOUD_WRITERS)}")
    atomic_write_bytes(path, writer(cloud))


# ----------------------------------------------------------------------------------------- readers


class RangeGrid(NamedTuple):
    """An organised scan, as read by :func:`load_range_grid`."""

    points: np.ndarray  # (N, 3) float64 metres
    grid: np.ndarray    # (rows, cols) int64 index into ``points``, -1 where the scanner saw nothing


def load_cloud(path: str | Path) -> PointCloud:
    """Read a point cloud in the format given by the file extension (see :data:`CLOUD_READERS`).

    Parameters
    ----------
    path : str or Path
        ``.ply`` (ASCII or binary; vertex ``x y z`` [``nx ny nz``] [``red green blue``]; other elements
        such as faces or a range grid are skipped), ``.pcd`` (ASCII or binary; ``x y z``
        [``normal_x normal_y normal_z``] [``rgb``/``rgba``]), ``.xyz`` / ``.txt`` (3 or 6 columns, ``#``
        comments) or ``.npy`` ((N, 3), (N, 6) points + normals, (N, 9) points + normals + colours).
        Coordinates in metres.

    Returns
    -------
    PointCloud
        (N, 3) float64 points; normals and colours (float32 in [0, 1]) when the file has them. Rows
        whose point has a NaN or infinite coordinate are dropped.

    Raises
    ------
    FileFormatError
        If the suffix is unknown, the file is missing, malformed or truncated, or no finite point is left.
    """
    path = Path(path)
    reader = CLOUD_READERS.get(path.suffix.lower())
    if reader is None:
        raise FileFormatError(f"{path}: unknown point cloud format {path.suffix!r}; known: "
                              f"{', '.join(CLOUD_READERS)}")
    return reader(path)


def load_range_grid(path: str | Path) -> RangeGrid:
    """Read a Stanford / Cyberware range-grid PLY as an organised scan.

    The header gives the grid size as ``obj_info num_cols C`` and ``obj_info num_rows R``; element
    ``range_grid`` has R * C entries in row-major order, each a list of 0 or 1 vertex indices.

    Returns
    -------
    RangeGrid
        ``points``: (N, 3) float64 metres, the finite vertices in file order; ``grid``: (R, C) int64,
        the index into ``points`` seen at each grid cell, -1 where the cell is empty.

    Raises
    ------
    FileFormatError
        If the file is missing, malformed or truncated, is not a range-grid PLY (no ``range_grid``
        element or no ``num_rows`` / ``num_cols``), an entry lists more than one vertex or an index is
        out of range, or no finite vertex is left.
    """
    path = Path(path)
    if path.suffix.lower() != ".ply":
        raise FileFormatError(f"{path}: a range grid is read from a '.ply' file, found {path.suffix!r}")
    header, elements = _read_ply(path, ("vertex", "range_grid"))
    try:
        rows, cols = int(header.obj_info["num_rows"]), int(header.obj_info["num_cols"])
    except (KeyError, ValueError) as exc:
        found = {k: v for k, v in header.obj_info.items() if k in ("num_rows", "num_cols")}
        raise FileFormatError(f"{path}: expected header lines 'obj_info num_rows <int>' and 'obj_info "
                              f"num_cols <int>', found {found or 'neither'}") from exc
    grid_element = header.element("range_grid")
    props = grid_element.properties
    if len(props) != 1 or props[0].count_dtype is None:
        raise FileFormatError(f"{path}: expected element 'range_grid' to have one list property (vertex "
                              f"indices), found {[p.name for p in props]}")
    if grid_element.count != rows * cols:
        raise FileFormatError(f"{path}: expected {rows} x {cols} = {rows * cols} range_grid entries "
                              f"(obj_info num_rows x num_cols), found {grid_element.count}")
    lists = elements["range_grid"][props[0].name]
    if len(lists.counts) and lists.counts.max() > 1:
        k = int(np.argmax(lists.counts > 1))
        raise FileFormatError(f"{path}: range_grid entry {k} lists {lists.counts[k]} vertices, expected 0 or 1")
    points = _ply_points(path, header, elements["vertex"])
    index = np.full(rows * cols, -1, dtype=np.int64)
    index[lists.counts == 1] = lists.items
    bad = (index < -1) | (index >= len(points))
    if bad.any():
        k = int(np.argmax(bad))
        raise FileFormatError(f"{path}: range_grid entry {k} refers to vertex {index[k]}, expected an index "
                              f"in [0, {len(points)})")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():  # drop non-finite vertices and renumber the grid
        new_index = np.cumsum(finite) - 1
        index = np.where(index >= 0, np.where(finite[index], new_index[index], -1), -1)
        points = points[finite]
    if len(points) == 0:
        raise FileFormatError(f"{path}: expected at least one finite vertex, found none")
    return RangeGrid(points, index.reshape(rows, cols))


# ---- shared helpers


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError as exc:
        raise FileFormatError(f"{path}: point cloud file not found") from exc
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read point cloud file: {exc.strerror or exc}") from exc


def _make_cloud(path: Path, points: np.ndarray, normals: np.ndarray | None = None,
                colours: np.ndarray | None = None) -> PointCloud:
    """A PointCloud of the rows whose point is finite; FileFormatError if none is."""
    points = np.asarray(points, dtype=np.float64)
    keep = np.isfinite(points).all(axis=1)
    if not keep.all():
        points = points[keep]
        normals = None if normals is None else normals[keep]
        colours = None if colours is None else colours[keep]
    if len(points) == 0:
        found = "an empty cloud" if keep.size == 0 else f"{keep.size} points, none of them finite"
        raise FileFormatError(f"{path}: expected at least one point, found {found}")
    return PointCloud(points, colours=colours, normals=normals)


def _plural(name: str) -> str:
    return {"vertex": "vertices", "face": "faces", "point": "points"}.get(name, f"'{name}' entries")


_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 32]] = True


def _ascii_rows(path: Path, data: bytes, offset: int, n_rows: int, first_line: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Numbers on the first ``n_rows`` non-blank lines of ``data[offset:]``, vectorised.

    Returns all values in order (float64), the count of values on each row and each row's 1-based line
    number in the file (``first_line`` is the number of the line at ``offset``). Fewer rows are returned
    when the text ends early; a token that is not a number raises FileFormatError naming its line.
    """
    buf = np.frombuffer(data, dtype=np.uint8, offset=offset)
    newlines = np.flatnonzero(buf == 10)
    if len(newlines) > n_rows > 0:  # look at the first n_rows lines only, unless some of them are blank
        rows = _ascii_rows(path, data[:offset + newlines[n_rows - 1] + 1], offset, n_rows, first_line)
        if len(rows[1]) == n_rows:
            return rows
    space = _SPACE[buf]
    starts = ~space
    starts[1:] &= space[:-1]
    newlines = np.flatnonzero(buf == 10)
    line_of_token = np.searchsorted(newlines, np.flatnonzero(starts))
    per_line = np.bincount(line_of_token, minlength=len(newlines) + 1)
    lines = np.flatnonzero(per_line)[:n_rows]
    counts = per_line[lines]
    if len(lines) == 0:
        return np.empty(0), counts, lines + first_line
    end = newlines[lines[-1]] if lines[-1] < len(newlines) else len(buf)
    text = data[offset:offset + end]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # numpy warns (instead of raising) on text it cannot parse
            values = np.fromstring(text, dtype=np.float64, sep=" ")
    except (ValueError, DeprecationWarning):
        values = None
    if values is None or len(values) != counts.sum():
        # Slow path, only to name the culprit: find the first token that is not a number.
        for k, token in enumerate(text.split()):
            try:
                float(token)
            except ValueError:
                line = first_line + int(line_of_token[k])
                raise FileFormatError(f"{path}: line {line}: expected a number, found "
                                      f"{token[:40].decode('latin-1')!r}") from None
        raise FileFormatError(f"{path}: expected whitespace-separated numbers after the header, found text "
                              f"numpy cannot parse")
    return values, counts, lines + first_line


@dataclass(frozen=True)
class _Lists:
    """A PLY list property: one variable-length list per row, stored flat."""

    counts: np.ndarray  # (n,) int64 length of each row's list
    items: np.ndarray   # (counts.sum(),) the lists' items, row after row


def _ragged_index(starts: np.ndarray, counts: np.ndarray, step: int = 1) -> np.ndarray:
    """Flat positions ``starts[i] + step * j`` for j < counts[i], row after row."""
    total = int(counts.sum())
    first = np.repeat(np.cumsum(counts) - counts, counts)
    return np.repeat(starts, counts) + (np.arange(total) - first) * step


# ---- PLY

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
class _PlyHeader:
    byte_order: str | None           # None for ASCII, "<" or ">" for binary
    elements: tuple[_PlyElement, ...]
    obj_info: dict[str, str]         # Stanford "obj_info key value" lines
    data_start: int                  # byte offset of the body
    n_lines: int                     # lines in the header

    def element(self, name: str) -> _PlyElement:
        return next(e for e in self.elements if e.name == name)


def _parse_ply_header(path: Path, data: bytes) -> _PlyHeader:
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
    return _PlyHeader(_PLY_FORMATS[fmt], tuple(elements), obj_info, end.end(), len(lines) + 1)


def _truncated(path: Path, element: _PlyElement | str, declared: int, found: int) -> FileFormatError:
    what = _plural(element.name if isinstance(element, _PlyElement) else element)
    return FileFormatError(f"{path}: header declares {declared} {what} but the file ends after {found}")


def _read_ply(path: Path, wanted: tuple[str, ...]) -> tuple[_PlyHeader, dict[str, dict]]:
    """Header and the ``wanted`` elements (property name -> (n,) array or _Lists) of a PLY file.

    Elements before the last wanted one are parsed and skipped; those after it are not read.
    """
    data = _read_bytes(path)
    header = _parse_ply_header(path, data)
    names = [e.name for e in header.elements]
    for name in wanted:
        if name not in names:
            raise FileFormatError(f"{path}: expected a PLY element {name!r}, found elements {names}")
    elements = header.elements[:max(names.index(name) for name in wanted) + 1]
    out = {}
    if header.byte_order is None:
        n_rows = sum(e.count for e in elements)
        values, counts, lines = _ascii_rows(path, data, header.data_start, n_rows, header.n_lines + 1)
        row = start = 0
        for e in elements:
            if len(counts) < row + e.count:
                raise _truncated(path, e, e.count, len(counts) - row)
            rows = slice(row, row + e.count)
            out[e.name] = _split_ascii_rows(path, e, values, counts[rows], lines[rows], start)
            start += int(counts[rows].sum())
            row += e.count
    else:
        offset = header.data_start
        for e in elements:
            out[e.name], offset = _read_binary_element(path, data, offset, e, header.byte_order)
    return header, {name: out[name] for name in wanted}


def _split_ascii_rows(path: Path, e: _PlyElement, values: np.ndarray, counts: np.ndarray,
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
            out[p.name] = _Lists(n, values[_ragged_index(pos + 1, n)])
            pos += 1 + n
    check(pos != row_end, f"{len(e.properties)} properties")
    return out


def _read_binary_element(path: Path, data: bytes, offset: int, e: _PlyElement, bo: str
                         ) -> tuple[dict, int]:
    """Element ``e`` starting at byte ``offset``: (property name -> array or _Lists, offset after it)."""
    if not e.properties or e.count == 0:
        empty = {p.name: np.empty(0, p.dtype) if p.count_dtype is None
                 else _Lists(np.empty(0, np.int64), np.empty(0, p.dtype)) for p in e.properties}
        return empty, offset
    available = len(data) - offset
    if all(p.count_dtype is None for p in e.properties):
        dt = np.dtype([(p.name, bo + p.dtype) for p in e.properties])
        if available < e.count * dt.itemsize:
            raise _truncated(path, e, e.count, max(available, 0) // dt.itemsize)
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
                    out[p.name] = _Lists(np.full(e.count, k, dtype=np.int64), items)
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
            out[p.name] = _Lists(n, _gather(u8, _ragged_index(starts, n, size), bo + p.dtype))
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
                    raise _truncated(path, e, e.count, row)
                n = length.unpack_from(data, pos)[0]
                if n < 0:
                    raise FileFormatError(f"{path}: {e.name!r} row {row}: expected a list length >= 0, found {n}")
                pos += n * item_size
            pos += size
        if pos > end:
            raise _truncated(path, e, e.count, row)
    return np.array(offsets, dtype=np.int64).reshape(n_rows, len(steps)), pos


def _gather(u8: np.ndarray, offsets: np.ndarray, dtype: str) -> np.ndarray:
    """Values of ``dtype`` at byte ``offsets`` of the uint8 buffer ``u8`` (vectorised)."""
    dt = np.dtype(dtype)
    return u8[offsets[:, None] + np.arange(dt.itemsize)].view(dt).reshape(-1)


def _ply_points(path: Path, header: _PlyHeader, vertex: dict) -> np.ndarray:
    props = {p.name: p for p in header.element("vertex").properties}
    if not all(c in props and props[c].count_dtype is None for c in "xyz"):
        raise FileFormatError(f"{path}: expected vertex properties x, y, z, found {', '.join(props) or 'none'}")
    return np.column_stack([np.asarray(vertex[c], dtype=np.float64) for c in "xyz"])


def _read_ply_cloud(path: Path) -> PointCloud:
    header, elements = _read_ply(path, ("vertex",))
    vertex = elements["vertex"]
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
    return _make_cloud(path, _ply_points(path, header, vertex), normals, colours)


# ---- PCD (Point Cloud Library)

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def _read_pcd(path: Path) -> PointCloud:
    data = _read_bytes(path)
    header, pos, n_lines = {}, 0, 0
    while "DATA" not in header:
        newline = data.find(b"\n", pos)
        if newline < 0 or n_lines > 100:
            raise FileFormatError(f"{path}: expected a PCD header ending in a 'DATA ascii|binary' line, "
                                  f"found none")
        line = data[pos:newline].decode("latin-1").strip()
        pos, n_lines = newline + 1, n_lines + 1
        if not line or line.startswith("#"):
            continue
        key, *words = line.split()
        if key not in _PCD_KEYS:
            raise FileFormatError(f"{path}: PCD header line {n_lines}: expected one of {', '.join(_PCD_KEYS)}, "
                                  f"found {line[:40]!r}")
        header[key] = words
    try:
        names = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(names))]
        n = int(header["POINTS"][0]) if "POINTS" in header else \
            int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
        dtypes = [{"F": "f", "I": "i", "U": "u"}[t] + str(s) for t, s in zip(types, sizes)]
        for dt in dtypes:
            np.dtype(dt)
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise FileFormatError(f"{path}: expected PCD header lines FIELDS, SIZE, TYPE (F, I or U), COUNT and "
                              f"POINTS with matching entries, found {header}") from exc
    if not len(names) == len(sizes) == len(types) == len(counts):
        raise FileFormatError(f"{path}: expected as many SIZE, TYPE and COUNT entries as FIELDS ({len(names)}), "
                              f"found {len(sizes)}, {len(types)} and {len(counts)}")
    kind = header["DATA"][0] if header["DATA"] else ""
    columns = {}
    if kind == "binary":
        fields = [(f"_{j}", "<" + ("u4" if name in ("rgb", "rgba") and dt == "f4" else dt), (c,))
                  for j, (name, dt, c) in enumerate(zip(names, dtypes, counts))]
        dt = np.dtype(fields)
        if len(data) - pos < n * dt.itemsize:
            raise _truncated(path, "point", n, (len(data) - pos) // max(dt.itemsize, 1))
        rec = np.frombuffer(data, dtype=dt, count=n, offset=pos)
        for j, name in enumerate(names):
            columns.setdefault(name, rec[f"_{j}"][:, 0])
    elif kind == "ascii":
        width = sum(counts)
        values, row_counts, lines = _ascii_rows(path, data, pos, n, n_lines + 1)
        if len(row_counts) < n:
            raise _truncated(path, "point", n, len(row_counts))
        if np.any(row_counts != width):
            k = int(np.argmax(row_counts != width))
            raise FileFormatError(f"{path}: line {lines[k]}: expected {width} numbers ({' '.join(names)}), "
                                  f"found {row_counts[k]}")
        table = values.reshape(n, width)
        first = np.cumsum(counts) - counts
        for name, dt, j in zip(names, dtypes, first):
            col = table[:, j]
            if name in ("rgb", "rgba"):  # packed 0xAARRGGBB, stored as a float's bits or an integer
                col = col.astype(np.float32).view(np.uint32) if dt == "f4" else col.astype(np.uint32)
            columns.setdefault(name, col)
    elif kind == "binary_compressed":
        raise FileFormatError(f"{path}: PCD 'DATA binary_compressed' is not supported; convert the file to "
                              f"binary or ascii first (e.g. pcl_convert_pcd_ascii_binary in.pcd out.pcd 1)")
    else:
        raise FileFormatError(f"{path}: expected PCD 'DATA ascii' or 'DATA binary', found {' '.join(header['DATA'])!r}")

    if not all(c in columns for c in "xyz"):
        raise FileFormatError(f"{path}: expected PCD fields x, y, z, found {' '.join(names)}")
    points = np.column_stack([columns[c].astype(np.float64) for c in "xyz"])
    normals = None
    if all(f"normal_{c}" in columns for c in "xyz"):
        normals = np.column_stack([columns[f"normal_{c}"].astype(np.float64) for c in "xyz"])
    colours = None
    packed = columns.get("rgb", columns.get("rgba"))
    if packed is not None:
        packed = packed.astype(np.uint32)
        colours = np.column_stack([(packed >> s) & 0xFF for s in (16, 8, 0)]).astype(np.float32) / 255
    return _make_cloud(path, points, normals, colours)


# ---- text and NumPy


def _read_xyz(path: Path) -> PointCloud:
    data = _read_bytes(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
            table = np.loadtxt(io.BytesIO(data), dtype=np.float64, comments="#", ndmin=2)
    except ValueError as exc:
        reason = str(exc).split(";")[0]
        raise FileFormatError(f"{path}: expected rows of 3 (x y z) or 6 (x y z nx ny nz) numbers, but {reason}") \
            from None
    if table.size == 0:
        raise FileFormatError(f"{path}: expected at least one point, found an empty cloud")
    if table.shape[1] not in (3, 6):
        raise FileFormatError(f"{path}: expected rows of 3 (x y z) or 6 (x y z nx ny nz) numbers, found "
                              f"{table.shape[1]} columns")
    return _make_cloud(path, table[:, :3], table[:, 3:6] if table.shape[1] == 6 else None)


def _read_npy(path: Path) -> PointCloud:
    data = _read_bytes(path)
    expected = "an .npy array of shape (N, 3), (N, 6) points + normals or (N, 9) points + normals + colours"
    if not data.startswith(b"\x93NUMPY"):
        raise FileFormatError(f"{path}: expected {expected}, found no .npy header (file starts {data[:8]!r})")
    try:
        a = np.load(io.BytesIO(data), allow_pickle=False)
    except (ValueError, EOFError, OSError) as exc:
        raise FileFormatError(f"{path}: expected {expected}, cannot read it ({exc})") from None
    if a.ndim != 2 or a.shape[1] not in (3, 6, 9) or a.dtype.kind not in "fiu":
        raise FileFormatError(f"{path}: expected {expected}, found {a.dtype} {a.shape}")
    normals = a[:, 3:6] if a.shape[1] >= 6 else None
    if normals is not None and len(a) and np.isnan(normals).all():  # colours without normals
        normals = None
    return _make_cloud(path, a[:, :3], normals, a[:, 6:9] if a.shape[1] == 9 else None)


CLOUD_READERS = {".ply": _read_ply_cloud, ".pcd": _read_pcd, ".xyz": _read_xyz, ".txt": _read_xyz,
                 ".npy": _read_npy}


def to_open3d(cloud: PointCloud):
    """The cloud as an ``open3d.geometry.PointCloud`` (imports open3d)."""
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    if cloud.colours is not None:
        pc.colors = o3d.utility.Vector3dVector(cloud.colours.astype(np.float64))
    if cloud.normals is not None:
        pc.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pc
