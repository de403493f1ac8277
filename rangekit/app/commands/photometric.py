"""Photometric stereo on a DiLiGenT-style folder, written out: the work behind ``rangekit photometric``.

Outputs in ``out``: ``normals.npy`` (H, W, 3) float32 unit normals in the OpenCV camera frame (NaN outside
the mask), ``normals.png`` (RGB = (x, up, towards the viewer) / 2 + 1/2, as the benchmarks show them),
``albedo.png`` (scaled to its 99th percentile), ``depth.npy`` (H, W) float32 integrated depth and
``mesh.ply`` (pixel units, orthographic). Every file is written atomically (temporary file, fsync, rename):
an interrupted run leaves whole files or none, never a truncated one.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit._runtime.arguments import check_callable, check_choice, check_path
from rangekit.errors import naming
from rangekit.io import atomic_save_npy, write_png
from rangekit.progress import call_progress
from rangekit.formats.sessions.files import MESH_FILE

__all__ = ["photometric_folder"]


def photometric_folder(folder: str | Path, out: str | Path, *, method: str = "robust",
                      progress: Callable | None = None) -> Path:
    """Normals (``method`` "ls", "robust" or "uncalibrated"), albedo, depth and a mesh from ``folder``,
    written into ``out``; reports each step (and the angular error against Normal_gt.mat when the folder
    has one) through ``progress(msg)``. Returns ``out``."""
    check_path("folder", folder, what="a DiLiGenT-style folder")
    check_path("out", out, what="a folder")
    check_choice("method", method, ("ls", "robust", "uncalibrated"))
    check_callable("progress", progress)
    from rangekit.photometric import (angular_error, depth_to_mesh, integrate_normals, photometric_stereo,
                                      uncalibrated_photometric_stereo)
    from rangekit.photometric.diligent import load_diligent
    from rangekit.formats.meshes import save_mesh
    from rangekit.surface.mesh import TriangleMesh

    t0 = time.perf_counter()
    data = load_diligent(folder)
    call_progress(progress, f"read {len(data.filenames)} images of {data.mask.shape[1]}x{data.mask.shape[0]} from "
                            f"{folder} ({int(data.mask.sum())} pixels in the mask) in {time.perf_counter() - t0:.1f} s")
    t1 = time.perf_counter()
    with naming(folder):  # the solvers see arrays; say which folder the images came from
        if method == "uncalibrated":
            res = uncalibrated_photometric_stereo(data.images, data.mask)
        else:
            res = photometric_stereo(data.images, data.lights, data.mask, method=method)
    call_progress(progress, f"normals ({method}) in {time.perf_counter() - t1:.1f} s"
                            + (f"; {res.interreflection}" if res.interreflection else ""))
    if data.normals_gt is not None:
        err = angular_error(res.normals, data.normals_gt, data.mask)
        call_progress(progress, f"angular error against Normal_gt.mat: mean {err.mean_deg:.3f} deg, median "
                                f"{err.median_deg:.3f} deg")
    t2 = time.perf_counter()
    depth = integrate_normals(res.normals, data.mask)
    V, F = depth_to_mesh(depth, data.mask, pixel_size=1.0)
    call_progress(progress, f"integrated the normals into depth and a mesh of {len(V):,} vertices in "
                            f"{time.perf_counter() - t2:.1f} s")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_save_npy(out / "normals.npy", res.normals.astype(np.float32))
    atomic_save_npy(out / "depth.npy", depth.astype(np.float32))
    n = np.nan_to_num(res.normals)
    # Colour code as the benchmarks show it: RGB = (x, up, towards the viewer) / 2 + 1/2.
    rgb = np.stack([n[..., 0], -n[..., 1], -n[..., 2]], axis=-1) * 0.5 + 0.5
    write_png(out / "normals.png", np.where(data.mask[..., None], np.rint(rgb * 255), 0).astype(np.uint8))
    albedo = np.nan_to_num(res.albedo if res.albedo.ndim == 2 else res.albedo.mean(axis=2))
    scale = np.percentile(albedo[data.mask], 99) if data.mask.any() else 1.0
    write_png(out / "albedo.png", np.rint(np.clip(albedo / max(scale, 1e-12), 0, 1) * 255).astype(np.uint8))
    save_mesh(out / MESH_FILE, TriangleMesh(V, F), units="pixels (x, y on the image grid, z integrated depth)")
    return out
