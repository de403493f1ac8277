"""What each pixel of a camera sees of a mesh: the ray cast behind every mesh render of
:mod:`rangekit.rendering.snapshot` (reports, ``rangekit render``).

Open3D's ``RaycastingScene`` (:func:`rangekit.surface.raycast.mesh_scene`, one scene per mesh) finds the
triangle in float32; hit point, barycentrics and normals are recomputed in float64. Frames as in
:mod:`rangekit.rendering.snapshot`: world points in metres, OpenCV camera frame, maps (H, W[, k]).
"""

from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass

import numpy as np

from rangekit.budget import check_budget
from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.errors import InputError
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.raycast import mesh_scene, query_scene

__all__ = ["MESH_RENDER_BYTES_PER_PIXEL", "HITS_PER_MESH", "MeshHits", "raycast_mesh"]

#: Peak memory of a mesh render per image pixel, bytes (measured: a 2000x2000 mesh render takes 337 B/px more
#: than a 500x500 one), checked against the memory budget (rangekit.budget) before it starts.
MESH_RENDER_BYTES_PER_PIXEL = 384


@dataclass(frozen=True, eq=False)
class MeshHits:
    """What each camera pixel sees of a mesh. Maps are (H, W[, k]); world frame, metres."""

    hit: np.ndarray       # (H, W) bool
    xyz: np.ndarray       # (H, W, 3) float64 world hit point; NaN where no hit
    normal: np.ndarray    # (H, W, 3) float64 unit face normal (world) facing the camera; NaN where no hit
    triangle: np.ndarray  # (H, W) int64 triangle index; -1 where no hit
    bary: np.ndarray      # (H, W, 2) float64 (b1, b2): p = (1 - b1 - b2) v0 + b1 v1 + b2 v2 (Open3D uvs); NaN
    smooth_normal: np.ndarray  # (H, W, 3) area-weighted vertex normals interpolated with ``bary``, facing
                               # the camera; NaN where no hit (for shading dense meshes without facet noise)


#: Hits kept per mesh (while the mesh lives): the report shows one mesh from the same sides shaded, as a
#: heat map and as the quality map, so each camera's cast is made once.
HITS_PER_MESH = 8
_HITS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_HITS_LOCK = threading.Lock()


def _camera_key(camera: PinholeCamera) -> bytes:
    """Bytes that differ between cameras casting different rays (lens, size, pose)."""
    return b"".join(np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in
                    (camera.K, camera.dist, camera.T_world_cam, [camera.width, camera.height]))


def raycast_mesh(mesh: TriangleMesh, camera: PinholeCamera) -> MeshHits:
    """Cast the ray of every pixel centre of ``camera`` at ``mesh`` (first hit, both faces).

    Open3D finds the triangle in float32 (coordinates relative to the mesh centre); hit point and
    barycentrics are then recomputed in float64 against that triangle (Moller-Trumbore), as the simulator does.
    The last :data:`HITS_PER_MESH` results of each mesh object are kept (read-only) while it lives: a
    second call with an equal camera returns the same hits without casting.
    """
    if not isinstance(mesh, TriangleMesh) or len(mesh.triangles) == 0:
        raise InputError(f"raycast_mesh: expected a TriangleMesh with triangles, found {mesh!r}")
    H, W = camera.height, camera.width
    check_budget(H * W * MESH_RENDER_BYTES_PER_PIXEL, f"ray casting a {W}x{H} image")
    key = _camera_key(camera)
    with _HITS_LOCK:
        known = _HITS.setdefault(mesh, {})
        if key in known:
            return known[key]
    hits = _cast_mesh(mesh, camera)
    for a in vars(hits).values():
        a.flags.writeable = False
    with _HITS_LOCK:
        while len(known) >= HITS_PER_MESH:
            known.pop(next(iter(known)))
        known[key] = hits
    return hits


def _cast_mesh(mesh: TriangleMesh, camera: PinholeCamera) -> MeshHits:
    """:func:`raycast_mesh` without the cache."""
    H, W = camera.height, camera.width

    o, d = world_pixel_rays(camera)
    ok = np.all(np.isfinite(d), axis=1)
    d_cast = np.where(ok[:, None], d, [0.0, 0.0, 1.0])
    scene, c = mesh_scene(mesh)      # built once per mesh: the report renders one mesh ten times
    out = query_scene(scene, "cast_rays", np.concatenate([o - c, d_cast], axis=1).astype(np.float32))
    t32 = out["t_hit"].astype(np.float64)
    hit = ok & np.isfinite(t32)
    tri = np.full(H * W, -1, np.int64)
    tri[hit] = out["primitive_ids"][hit]
    oh, dh = o[hit], d[hit]
    v0, v1, v2 = (mesh.vertices[mesh.triangles[tri[hit], k]] for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    pvec, tvec = np.cross(dh, e2), oh - v0
    qvec = np.cross(tvec, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        det = np.einsum("ij,ij->i", e1, pvec)
        t = np.einsum("ij,ij->i", e2, qvec) / det
        b = np.column_stack([np.einsum("ij,ij->i", tvec, pvec), np.einsum("ij,ij->i", dh, qvec)]) / det[:, None]
    bad = ~(np.isfinite(t) & np.all(np.isfinite(b), axis=1))  # degenerate triangle: keep Open3D's float32
    t[bad], b[bad] = t32[hit][bad], out["primitive_uvs"][hit][bad]
    n = np.cross(e1, e2)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n *= -np.sign(np.einsum("ij,ij->i", n, dh) + 1e-300)[:, None]  # face the camera
    # Smooth normals: area-weighted vertex normals (unnormalised face cross products summed per vertex).
    F, vn = mesh.triangles, mesh.normal_sums
    w = np.column_stack([1 - b.sum(axis=1), b])
    ns = np.einsum("mk,mkc->mc", w, vn[F[tri[hit]]])
    with np.errstate(invalid="ignore", divide="ignore"):
        ns /= np.linalg.norm(ns, axis=1, keepdims=True)
    ns = np.where(np.all(np.isfinite(ns), axis=1)[:, None], ns, n)
    ns *= -np.sign(np.einsum("ij,ij->i", ns, dh) + 1e-300)[:, None]
    xyz, normal, bary = np.full((H * W, 3), np.nan), np.full((H * W, 3), np.nan), np.full((H * W, 2), np.nan)
    smooth = np.full((H * W, 3), np.nan)
    xyz[hit], normal[hit], bary[hit], smooth[hit] = oh + t[:, None] * dh, n, b, ns
    return MeshHits(hit.reshape(H, W), xyz.reshape(H, W, 3), normal.reshape(H, W, 3), tri.reshape(H, W),
                    bary.reshape(H, W, 2), smooth.reshape(H, W, 3))
