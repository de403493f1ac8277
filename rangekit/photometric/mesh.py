"""Triangulate a depth map's neighbouring valid pixels into a mesh (vertices and faces)."""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError
from rangekit.photometric.integrate import intrinsics_of

__all__ = ["depth_to_mesh"]


def depth_to_mesh(depth, mask=None, *, pixel_size: float | None = None,
                  camera=None) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate neighbouring valid depth pixels.

    Each 2x2 block of valid pixels gives two triangles, a block with three valid pixels one; faces wind
    so their normals face the camera (towards -z).

    Parameters
    ----------
    depth : (H, W) float, NaN where invalid
    mask : (H, W) bool, optional (default: finite depth)
    pixel_size : float, optional
        Orthographic: vertex ``(u * pixel_size, v * pixel_size, Z)``; default 1 (pixel units).
    camera : PinholeCamera or (3, 3) K, optional
        Perspective: vertex ``Z * K^-1 [u, v, 1]`` (metres, camera frame). Excludes ``pixel_size``.

    Returns
    -------
    vertices : (V, 3) float64, one per valid pixel in row-major order
    faces : (F, 3) int64 indices into ``vertices``
    """
    Z = np.asarray(depth, dtype=np.float64)
    if Z.ndim != 2:
        raise InputError(f"depth: expected (H, W), found shape {Z.shape}")
    if camera is not None and pixel_size is not None:
        raise InputError("depth_to_mesh: give pixel_size (orthographic) or camera (perspective), not both")
    valid = np.isfinite(Z) if mask is None else (np.asarray(mask, dtype=bool) & np.isfinite(Z))
    if not valid.any():
        raise InputError("depth_to_mesh: no valid depth pixel")
    H, W = Z.shape
    vv, uu = np.nonzero(valid)
    z = Z[valid]
    if camera is None:
        s = 1.0 if pixel_size is None else float(pixel_size)
        V = np.column_stack([uu * s, vv * s, z])
    else:
        K = intrinsics_of(camera)
        V = np.linalg.solve(K, np.vstack([uu, vv, np.ones_like(uu)])).T * z[:, None]
    idx = np.full((H, W), -1, dtype=np.int64)
    idx[valid] = np.arange(len(z))
    c00, c10 = idx[:-1, :-1], idx[:-1, 1:]   # "10": u + 1
    c01, c11 = idx[1:, :-1], idx[1:, 1:]     # "01": v + 1
    v00, v10, v01, v11 = c00 >= 0, c10 >= 0, c01 >= 0, c11 >= 0
    tris = [
        (v00 & v01 & v10, (c00, c01, c10)),           # upper-left of a full quad, or 11 missing
        (v10 & v01 & v11, (c10, c01, c11)),           # lower-right of a full quad, or 00 missing
        (v00 & v01 & v11 & ~v10, (c00, c01, c11)),    # 10 missing
        (v00 & v11 & v10 & ~v01, (c00, c11, c10)),    # 01 missing
    ]
    F = np.concatenate([np.column_stack([c[sel] for c in corners]) for sel, corners in tris])
    return V, F.astype(np.int64)
