"""PCD files (Point Cloud Library).

Reading: ASCII and binary bodies with vectorised numpy (their errors name the file, the expected and the
found value; Open3D's reader prints a warning and returns an empty cloud instead); ``binary_compressed``
(LZF, what ``open3d.io.write_point_cloud(..., compressed=True)`` and PCL write) through ``open3d.io``.
Writing (:func:`pcd_bytes`): binary, float32 ``x y z`` (metres), float32 normals, packed ``rgb`` (U4,
0x00RRGGBB as Open3D writes it) and float32 ``sigma``. float32 coordinates as PCL's ``PointXYZ`` and Open3D
write them: Open3D 0.19's ``o3d.io.read_point_cloud`` reads ``SIZE 8`` coordinates as zeros, silently.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError, shown
from rangekit.formats.parsing import ascii_rows, cloud_of_finite_rows, read_bytes, truncated_error
from rangekit.surface.cloud import PointCloud

__all__ = ["read_pcd", "pcd_bytes"]

_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def read_pcd(path: Path) -> PointCloud:
    """A PCL ``.pcd`` cloud (ASCII or binary; x y z, normal_x/y/z, packed rgb/rgba), rows not finite dropped."""
    data = read_bytes(path)
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
    if any(s not in (1, 2, 4, 8) for s in sizes) or any(c < 1 for c in counts) or n < 0:
        raise FileFormatError(f"{path}: expected PCD SIZE entries of 1, 2, 4 or 8 bytes, COUNT entries >= 1 and "
                              f"POINTS >= 0, found SIZE {' '.join(header['SIZE'])}, COUNT "
                              f"{' '.join(map(str, counts))}, {n} points")
    kind = header["DATA"][0] if header["DATA"] else ""
    columns = {}
    if kind == "binary":
        fields = [(f"_{j}", "<" + ("u4" if name in ("rgb", "rgba") and dt == "f4" else dt), (c,))
                  for j, (name, dt, c) in enumerate(zip(names, dtypes, counts))]
        dt = np.dtype(fields)
        if len(data) - pos < n * dt.itemsize:
            raise truncated_error(path, "point", n, (len(data) - pos) // max(dt.itemsize, 1))
        rec = np.frombuffer(data, dtype=dt, count=n, offset=pos)
        for j, name in enumerate(names):
            columns.setdefault(name, rec[f"_{j}"][:, 0])
    elif kind == "ascii":
        width = sum(counts)
        values, row_counts, lines = ascii_rows(path, data, pos, n, n_lines + 1)
        if len(row_counts) < n:
            raise truncated_error(path, "point", n, len(row_counts))
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
        return _read_compressed(path, names, n)
    else:
        raise FileFormatError(f"{path}: expected PCD 'DATA ascii', 'binary' or 'binary_compressed', found {shown(' '.join(header['DATA']))}")

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
    sigma = columns["sigma"].astype(np.float64) if "sigma" in columns else None
    return cloud_of_finite_rows(path, points, normals, colours, sigma)



def _read_compressed(path: Path, names: list[str], n: int) -> PointCloud:
    """A ``DATA binary_compressed`` PCD through ``open3d.io`` (points float64, normals, colours)."""
    import open3d as o3d

    if not all(c in names for c in "xyz"):
        raise FileFormatError(f"{path}: expected PCD fields x, y, z, found {' '.join(names)}")
    pc = o3d.io.read_point_cloud(str(path), format="pcd", remove_nan_points=False, remove_infinite_points=False)
    if len(pc.points) != n:
        raise FileFormatError(f"{path}: header declares {n} points but Open3D read {len(pc.points)} from the "
                              f"binary_compressed body (truncated or corrupt)")
    colours = np.asarray(pc.colors) if pc.has_colors() else None
    return cloud_of_finite_rows(path, np.asarray(pc.points), np.asarray(pc.normals) if pc.has_normals() else None,
                                colours)


def pcd_bytes(cloud: PointCloud) -> bytes:
    """``cloud`` as a binary PCD (v0.7): float32 x y z, float32 normal_x/y/z, U4 rgb, float32 sigma (the
    optional ones when the cloud has them)."""
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if cloud.normals is not None:
        fields += [("normal_x", "<f4"), ("normal_y", "<f4"), ("normal_z", "<f4")]
    if cloud.colours is not None:
        fields += [("rgb", "<u4")]
    if cloud.sigma is not None:
        fields += [("sigma", "<f4")]
    rec = np.empty(len(cloud), dtype=fields)
    rec["x"], rec["y"], rec["z"] = cloud.points.T
    if cloud.normals is not None:
        rec["normal_x"], rec["normal_y"], rec["normal_z"] = cloud.normals.T
    if cloud.colours is not None:
        rgb = np.clip(np.rint(cloud.colours * 255), 0, 255).astype(np.uint32)
        rec["rgb"] = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    if cloud.sigma is not None:
        rec["sigma"] = cloud.sigma
    kinds = {"f": "F", "u": "U", "i": "I"}
    header = ["# .PCD v0.7 - Point Cloud Data file format (rangekit, metres)", "VERSION 0.7",
              "FIELDS " + " ".join(rec.dtype.names),
              "SIZE " + " ".join(str(rec.dtype[f].itemsize) for f in rec.dtype.names),
              "TYPE " + " ".join(kinds[rec.dtype[f].kind] for f in rec.dtype.names),
              "COUNT " + " ".join("1" for _ in rec.dtype.names),
              f"WIDTH {len(rec)}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {len(rec)}", "DATA binary"]
    return b"".join([("\n".join(header) + "\n").encode("ascii"), memoryview(rec).cast("B")])
