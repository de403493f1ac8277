"""Point cloud files, chosen by extension.

Writers (:data:`CLOUD_WRITERS`, :func:`save_cloud`): ``.ply`` (binary little-endian, float64 xyz, float32
normals, uint8 RGB, float32 ``sigma`` when the cloud has it; :mod:`rangekit.formats.ply`), ``.pcd`` (binary,
float32 xyz as PCL and Open3D read them, normals, rgb, sigma; :mod:`rangekit.formats.pcd`), ``.xyz`` (text ``x y z [nx ny nz]``),
``.npy`` ((N, 3), (N, 6) points + normals or (N, 9) points + normals + colours), ``.e57`` (points and
colours through pye57; :mod:`rangekit.formats.e57`). PLY and PCD keep ``sigma``. Writes are atomic.

Readers (:data:`CLOUD_READERS`, :func:`load_cloud`): ``.ply`` (ASCII and binary of either byte order;
extra elements such as faces or a Stanford ``range_grid`` are skipped), ``.pcd`` (PCL, ASCII, binary and
binary_compressed), ``.xyz`` / ``.txt``, ``.npy`` and ``.e57`` (every scan, poses applied). Rows whose point
is not finite are dropped. :func:`load_range_grid` reads a Stanford/Cyberware range-grid PLY as an
organised scan.
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from rangekit._runtime.arguments import check_instance, check_path
from rangekit.regular_files import check_regular_file
from rangekit.errors import FileFormatError
from rangekit.formats.parsing import cloud_of_finite_rows, read_bytes
from rangekit.formats.e57 import e57_bytes, read_e57
from rangekit.formats.pcd import pcd_bytes, read_pcd
from rangekit.formats.ply import ply_points, ply_vertex_attributes, ply_vertex_scalar, read_ply
from rangekit.formats.ply_write import cloud_ply_bytes, write_cloud_ply
from rangekit.io import atomic_write_bytes, atomic_write_with
from rangekit.surface.cloud import PointCloud
from rangekit.surface.convert import as_cloud

__all__ = ["save_cloud", "CLOUD_WRITERS", "load_cloud", "CLOUD_READERS", "RangeGrid", "load_range_grid"]


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


CLOUD_WRITERS = {".ply": cloud_ply_bytes, ".pcd": pcd_bytes, ".xyz": _write_xyz, ".npy": _write_npy,
                 ".e57": e57_bytes}


def save_cloud(path: str | Path, cloud, *, fields: dict[str, np.ndarray] | None = None) -> None:
    """Write ``cloud`` (any cloud :func:`rangekit.surface.convert.as_cloud` takes: a PointCloud, an (N, 3)
    array, an Open3D or trimesh cloud) in the format given by the file extension (:data:`CLOUD_WRITERS`),
    atomically. ``fields``: extra per-point properties (name -> (N,) array), PLY only (e.g. merged.ply's
    ``view``, :func:`rangekit.surface.cloud.view_index`)."""
    check_path("path", path, what="a point cloud file")
    check_instance("fields", fields, dict, "a dict of per-point arrays", optional=True)
    path = Path(path)
    writer = CLOUD_WRITERS.get(path.suffix.lower())
    if writer is None:
        raise FileFormatError(f"{path}: unknown point cloud format {path.suffix!r}; known: "
                              f"{', '.join(CLOUD_WRITERS)}")
    cloud = as_cloud(cloud, "save_cloud cloud")
    if fields and writer is not cloud_ply_bytes:
        raise FileFormatError(f"{path}: extra point fields ({', '.join(fields)}) are written to '.ply' only, "
                              f"found {path.suffix!r}")
    if writer is cloud_ply_bytes:   # straight into the file, a chunk of records at a time
        atomic_write_with(path, lambda f: write_cloud_ply(f, cloud, fields))
    else:
        atomic_write_bytes(path, writer(cloud))


class RangeGrid(NamedTuple):
    """An organised scan, as read by :func:`load_range_grid`."""

    points: np.ndarray  # (N, 3) float64 metres
    grid: np.ndarray    # (rows, cols) int64 index into ``points``, -1 where the scanner saw nothing


def load_cloud(path: str | Path) -> PointCloud:
    """Read a point cloud in the format given by the file extension (see :data:`CLOUD_READERS`).

    Parameters
    ----------
    path : str or Path
        ``.e57`` (every scan, placed by its pose; colours), ``.ply`` (ASCII or binary; vertex ``x y z`` [``nx ny nz``] [``red green blue``] [``sigma``]; other elements
        such as faces or a range grid are skipped), ``.pcd`` (ASCII, binary or binary_compressed; ``x y z``
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
        If the suffix is unknown, the file is missing or a folder, malformed or truncated, or no finite point
        is left.
    """
    path = Path(check_path("path", path, what="a point cloud file"))
    if path.is_dir():
        raise FileFormatError(f"{path}: is a folder, expected a point cloud file ({', '.join(CLOUD_READERS)})")
    reader = CLOUD_READERS.get(path.suffix.lower())
    if reader is None:
        raise FileFormatError(f"{path}: unknown point cloud format {path.suffix!r}; known: "
                              f"{', '.join(CLOUD_READERS)}")
    if not os.path.lexists(path):
        raise FileFormatError(f"{path}: point cloud file not found")
    check_regular_file(path, what=f"a point cloud file ({path.suffix.lower()})")   # /dev/urandom as u.xyz
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
    path = Path(check_path("path", path, what="a range-grid PLY file"))
    if path.suffix.lower() != ".ply":
        raise FileFormatError(f"{path}: a range grid is read from a '.ply' file, found {path.suffix!r}")
    header, elements = read_ply(path, ("vertex", "range_grid"))
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
    points = ply_points(path, header, elements["vertex"])
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


def _read_ply_cloud(path: Path) -> PointCloud:
    header, elements = read_ply(path, ("vertex",))
    points, normals, colours = ply_vertex_attributes(path, header, elements["vertex"])
    sigma = ply_vertex_scalar(header, elements["vertex"], "sigma")
    return cloud_of_finite_rows(path, points, normals, colours, sigma)


def _read_xyz(path: Path) -> PointCloud:
    data = read_bytes(path)
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
    return cloud_of_finite_rows(path, table[:, :3], table[:, 3:6] if table.shape[1] == 6 else None)


def _read_npy(path: Path) -> PointCloud:
    data = read_bytes(path)
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
    return cloud_of_finite_rows(path, a[:, :3], normals, a[:, 6:9] if a.shape[1] == 9 else None)


CLOUD_READERS = {".ply": _read_ply_cloud, ".pcd": read_pcd, ".xyz": _read_xyz, ".txt": _read_xyz,
                 ".npy": _read_npy, ".e57": read_e57}

