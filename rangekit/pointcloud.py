"""Point clouds with colours and normals, and their files (chosen by extension).

Formats: ``.ply`` (binary little-endian, float64 xyz, float32 normals, uint8 RGB; written with numpy,
no open3d needed), ``.xyz`` (text ``x y z [nx ny nz]``), ``.npy`` ((N, 3) or (N, 6/9) array). Writes are
atomic. Conversion to open3d / trimesh objects happens in :func:`to_open3d` only.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError, InputError
from rangekit.io import atomic_write_bytes

__all__ = ["PointCloud", "save_cloud", "CLOUD_WRITERS", "to_open3d"]


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
    cols = [cloud.points] + [a for a in (cloud.normals, cloud.colours) if a is not None]
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


def to_open3d(cloud: PointCloud):
    """The cloud as an ``open3d.geometry.PointCloud`` (imports open3d)."""
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    if cloud.colours is not None:
        pc.colors = o3d.utility.Vector3dVector(cloud.colours.astype(np.float64))
    if cloud.normals is not None:
        pc.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pc
