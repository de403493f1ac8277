"""E57 files (ASTM E2807, the laser-scanner exchange format) through ``pye57`` (libE57Format).

Writing (:func:`e57_bytes`): one scan, ``cartesianX/Y/Z`` in metres (pye57 writes float32: stored about
the centroid, which goes into the scan's float64 pose) and 8-bit colours when the cloud has them (E57 has no field for rangekit's normals or ``sigma``). Reading (:func:`read_e57`): every
scan of the file placed by its pose (``pye57``'s ``transform=True``), invalid points dropped, colours
when every scan has them; spherical scans are converted to cartesian by pye57.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError
from rangekit.formats.parsing import cloud_of_finite_rows
from rangekit.surface.cloud import PointCloud

__all__ = ["e57_bytes", "read_e57"]


def e57_bytes(cloud: PointCloud) -> bytes:
    """``cloud`` as the bytes of a one-scan E57 file (pye57 writes to a path: a temporary file)."""
    import pye57

    if len(cloud) == 0:
        raise FileFormatError("E57: cannot write an empty cloud (pye57 needs at least one point)")
    # pye57 stores coordinates as float32: store them about the centroid and put the centroid in the scan's
    # pose (float64), which every E57 reader applies; the error is then float32's over the cloud's extent.
    centre = cloud.points.mean(axis=0)
    local = cloud.points - centre
    data = {"cartesianX": local[:, 0].copy(), "cartesianY": local[:, 1].copy(), "cartesianZ": local[:, 2].copy(),
            "cartesianInvalidState": np.zeros(len(cloud), np.int8)}  # pye57's read_scan wants the field
    if cloud.colours is not None:
        rgb = np.clip(np.rint(cloud.colours * 255), 0, 255).astype(np.uint8)
        data.update(colorRed=rgb[:, 0].copy(), colorGreen=rgb[:, 1].copy(), colorBlue=rgb[:, 2].copy())
    with tempfile.TemporaryDirectory(prefix="rangekit-e57-") as tmp:
        path = Path(tmp) / "cloud.e57"
        with pye57.E57(str(path), mode="w") as e57:
            e57.write_scan_raw(data, name="rangekit point cloud, metres", rotation=np.array([1.0, 0.0, 0.0, 0.0]),
                               translation=centre)
        return path.read_bytes()


def read_e57(path: Path) -> PointCloud:
    """Every scan of an E57 file in the file's frame (poses applied), one PointCloud; rows not finite dropped."""
    import pye57

    if not path.is_file():
        raise FileFormatError(f"{path}: point cloud file not found")
    try:
        e57 = pye57.E57(str(path))
    except Exception as exc:  # libE57Format raises its own types for a file that is not E57
        raise FileFormatError(f"{path}: expected an E57 file, cannot open it: {exc}") from None
    points, colours = [], []
    try:
        with e57:
            if e57.scan_count == 0:
                raise FileFormatError(f"{path}: expected at least one scan in the E57 file, found none")
            for i in range(e57.scan_count):
                scan = e57.read_scan(i, colors=True, ignore_missing_fields=True)
                points.append(np.column_stack([scan[f"cartesian{c}"] for c in "XYZ"]).astype(np.float64))
                rgb = [scan.get(f"color{c}") for c in ("Red", "Green", "Blue")]
                colours.append(None if any(c is None for c in rgb) else np.column_stack(rgb).astype(np.float32) / 255)
    except FileFormatError:
        raise
    except Exception as exc:
        raise FileFormatError(f"{path}: cannot read the E57 scans: {exc}") from None
    rgb = np.concatenate(colours) if all(c is not None for c in colours) else None
    return cloud_of_finite_rows(path, np.concatenate(points), colours=rgb)
