"""The lit curve of a line laser: the laser plane sliced through the posed scene mesh, sampled densely,
kept where the laser and the camera both see it, projected with the camera's lens model.

No full ray cast per laser frame: the plane meets each triangle it crosses in one segment (exact in
float64: every point is on the plane to rounding and on its triangle), the segments are sampled at most
half a pixel apart in the image, and only those samples are ray cast, from the emitter (shadows, fan) and from the
camera (occlusion). Frames: world (the rig's world frame, the coded-light ground truth's ``xyz``),
metres; image coordinates are distorted pixels (pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import SceneError
from rangekit.rig.lasers import LineLaser
from rangekit.sim.scene.raycast import WorldMesh
from rangekit.surface.raycast import query_scene

__all__ = ["LitCurve", "slice_mesh", "fan_direction", "lit_curve", "cast_first_hits"]

_EDGES = np.array([[0, 1], [1, 2], [2, 0]])


@dataclass(frozen=True, eq=False)
class LitCurve:
    """Dense samples of one laser's lit curve that the laser and the camera both see (N samples)."""

    xyz: np.ndarray         # (N, 3) float64 world points on the laser plane and the mesh, metres
    uv: np.ndarray          # (N, 2) float64 distorted camera pixels of xyz
    face: np.ndarray        # (N,) int64 triangle of the world mesh holding the sample
    peak: np.ndarray        # (N,) float64 cos(incidence) x albedo at the laser's colour (x power: the renderer)
    sigma_px: np.ndarray    # (N,) float64 Gaussian sigma of the line profile across the line, camera pixels
    spacing_px: np.ndarray  # (N,) float64 image distance to the next sample along the curve, pixels


def slice_mesh(mesh: WorldMesh, plane: np.ndarray):
    """Segments where ``plane`` (4,) (n . X + d = 0) crosses the mesh's triangles.

    Returns (p0, p1, face, w0, w1): (M, 3) endpoints, (M,) triangle index, and (M, 3) barycentric-like
    vertex weights of each endpoint on its triangle (for interpolating normals and albedo). A vertex on
    the plane counts as on its positive side; triangles lying in the plane are not sliced.
    """
    s = mesh.vertices @ plane[:3] + plane[3]
    tri = mesh.triangles
    pos = s[tri] >= 0
    crossing = np.flatnonzero(pos.any(axis=1) & ~pos.all(axis=1))
    t3 = tri[crossing]
    sv = s[t3]                                            # (M, 3)
    pa, pb = pos[crossing][:, _EDGES[:, 0]], pos[crossing][:, _EDGES[:, 1]]
    cut = pa != pb                                        # exactly two edges per crossing triangle
    order = np.argsort(~cut, axis=1, kind="stable")[:, :2]  # (M, 2) the two cut edges
    ends, weights = [], []
    rows = np.arange(len(crossing))
    for k in range(2):
        e = _EDGES[order[:, k]]                           # (M, 2) local vertex indices
        sa, sb = sv[rows, e[:, 0]], sv[rows, e[:, 1]]
        t = sa / (sa - sb)
        va, vb = mesh.vertices[t3[rows, e[:, 0]]], mesh.vertices[t3[rows, e[:, 1]]]
        ends.append(va + t[:, None] * (vb - va))
        w = np.zeros((len(crossing), 3))
        w[rows, e[:, 0]] = 1.0 - t
        w[rows, e[:, 1]] += t
        weights.append(w)
    return ends[0], ends[1], crossing, weights[0], weights[1]


def fan_direction(laser: LineLaser) -> np.ndarray:
    """(3,) unit centre ray of the laser's fan: from the emitter towards the world origin's foot on the
    laser plane (the table centre for a plane through the turntable axis)."""
    n, d = laser.plane[:3], laser.plane[3]
    foot = -d * n
    v = foot - laser.origin
    norm = np.linalg.norm(v)
    if norm < 1e-9:
        raise SceneError(f"laser {laser.name!r}: its emitter is at the world origin's foot on its plane; the fan "
                         "direction is undefined")
    return v / norm


def cast_first_hits(rc_scene, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each ray in an Open3D ``RaycastingScene``: (t float64 with inf for misses, triangle id
    int64 with -1 for misses)."""
    rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
    out = query_scene(rc_scene, "cast_rays", rays)
    t = out["t_hit"].astype(np.float64)
    prim = out["primitive_ids"].astype(np.int64)
    prim[~np.isfinite(t)] = -1
    return t, prim


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _clear(rc_scene, source: np.ndarray, p: np.ndarray, face: np.ndarray, eps: float) -> np.ndarray:
    """(N,) bool: nothing but the sample's own triangle lies between ``source`` (3,) and each point."""
    v = p - source
    dist = np.linalg.norm(v, axis=1)
    t, prim = cast_first_hits(rc_scene, np.broadcast_to(source, p.shape), v / dist[:, None])
    return (prim == face) | (t >= dist - eps)


def lit_curve(mesh: WorldMesh, rc_scene, camera: PinholeCamera, laser: LineLaser, *,
              max_spacing_px: float = 0.5, eps: float = 2e-5) -> LitCurve:
    """The samples of ``laser``'s curve on ``mesh`` seen by ``camera`` and lit by the laser.

    Parameters
    ----------
    mesh : the posed scene (world frame); ``rc_scene`` its Open3D ray-casting scene (world coordinates).
    max_spacing_px : samples are at most this far apart in the image (pixels).
    eps : metres; an occluder must be this much nearer than the sample to hide it.

    A sample is kept if the emitter and the camera are on the same side of its triangle, it lies within
    the fan (half of ``fan_angle`` about :func:`fan_direction`), nothing hides it from the emitter or
    from the camera centre, and it projects into the image.
    """
    if laser.origin is None:
        raise SceneError(f"laser {laser.name!r}: the simulator needs the emitter position ('origin' in the rig "
                         "file) to cast its shadows")
    n_l = laser.plane[:3]
    p0, p1, face, w0, w1 = slice_mesh(mesh, laser.plane)
    # Emitter and camera on the same side of the triangle: n . X is constant on its plane, so per face.
    tri = mesh.triangles[face]
    v0 = mesh.vertices[tri[:, 0]]
    n_face = _unit(np.cross(mesh.vertices[tri[:, 1]] - v0, mesh.vertices[tri[:, 2]] - v0))
    sl = np.einsum("ij,ij->i", n_face, laser.origin - v0)
    sc = np.einsum("ij,ij->i", n_face, camera.center - v0)
    keep = sl * sc > 0
    p0, p1, face, w0, w1, n_face = p0[keep], p1[keep], face[keep], w0[keep], w1[keep], n_face[keep]
    W, H = camera.width, camera.height
    uv0, uv1 = camera.project(p0), camera.project(p1)
    len_px = np.linalg.norm(uv1 - uv0, axis=1)
    margin = 4.0
    inside = lambda uv: (uv[:, 0] > -margin) & (uv[:, 0] < W + margin) & (uv[:, 1] > -margin) & (uv[:, 1] < H + margin)
    keep = np.isfinite(len_px) & (inside(uv0) | inside(uv1))
    p0, p1, face, w0, w1, n_face, len_px = p0[keep], p1[keep], face[keep], w0[keep], w1[keep], n_face[keep], len_px[keep]
    count = np.maximum(np.ceil(len_px / max_spacing_px).astype(np.int64), 1)
    seg = np.repeat(np.arange(len(count)), count)
    start = np.cumsum(count) - count
    f = ((np.arange(seg.size) - start[seg]) + 0.5) / count[seg]
    p = p0[seg] + f[:, None] * (p1 - p0)[seg]
    fc = face[seg]
    to_l = laser.origin - p
    cos_fan = np.cos(laser.fan_angle / 2.0)
    in_fan = _unit(-to_l) @ fan_direction(laser) >= cos_fan
    cand = np.flatnonzero(in_fan)
    ok = _clear(rc_scene, laser.origin, p[cand], fc[cand], eps)
    cand = cand[ok]
    ok = _clear(rc_scene, camera.center, p[cand], fc[cand], eps)
    cand = cand[ok]
    uv = camera.project(p[cand])
    ok = (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    cand, uv = cand[ok], uv[ok]
    p, fc, seg = p[cand], fc[cand], seg[cand]
    n_face = n_face[seg]
    tri = mesh.triangles[fc]
    # Vertex weights of the sample on its triangle: shading normal and albedo interpolated.
    wv = (1.0 - f[cand])[:, None] * w0[seg] + f[cand][:, None] * w1[seg]
    n_s = _unit(np.einsum("ij,ijk->ik", wv, mesh.vertex_normals[tri]))
    n_s = np.where(mesh.face_smooth[fc][:, None], n_s, n_face)
    l_dir = _unit(laser.origin - p)
    cos_i = np.abs(np.einsum("ij,ij->i", n_s, l_dir))
    albedo = np.einsum("ij,ijk->ik", wv, mesh.vertex_albedo[tri])
    a = {"red": albedo[:, 0], "green": albedo[:, 1], "blue": albedo[:, 2]}.get(laser.channel, albedo.mean(axis=1))
    # Line width in the image: the profile across the sheet, sigma = line_width / 4, pulled back through
    # the surface (tangent c along the curve, q across it in the face) and the camera's Jacobian.
    c = _unit((p1 - p0)[seg])
    q = _unit(np.cross(n_face, c))
    h = 1e-5
    J_c = (camera.project(p + h * c) - uv) / h
    J_q = (camera.project(p + h * q) - uv) / h
    det = np.abs(J_c[:, 0] * J_q[:, 1] - J_c[:, 1] * J_q[:, 0])
    grad = np.abs(q @ n_l) * np.linalg.norm(J_c, axis=1) / np.maximum(det, 1e-300)  # |d s / d uv|, m per px
    sigma = (laser.line_width / 4.0) / np.maximum(grad, 1e-300)
    return LitCurve(xyz=p, uv=uv, face=fc, peak=cos_i * a, sigma_px=sigma,
                    spacing_px=(len_px / count)[seg])
