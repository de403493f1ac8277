"""PCD files (Point Cloud Library), ASCII and binary, read with vectorised numpy."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError
from rangekit.formats.parsing import ascii_rows, cloud_of_finite_rows, read_bytes, truncated_error
from rangekit.surface.cloud import PointCloud

__all__ = ["read_pcd"]

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
    return cloud_of_finite_rows(path, points, normals, colours)

