"""Which true-surface samples a laser-line scan sees lit: the "can see" of :func:`rangekit.sim.truth.evaluate.mesh_accuracy`
for ``light="laser"``.

A laser's light sheet is fixed in the world while the turntable turns the object; a surface point
``P`` (the object's frame, table at angle 0) lies on the sheet of laser ``k`` at the angles ``theta`` where
``n . M(theta) P + d = 0`` (``M`` the turntable motion, ``(n, d)`` the plane). In the table's frame that
is ``A cos(theta) + B sin(theta) + C = 0``, solved in closed form: two angles (or none, when the sheet never
reaches the point). The point is seen lit at such an angle when it is inside the camera's image, faces
the camera and the laser within the incidence limit, and nothing lies between it and either (rays cast
in the object's frame from the camera centre and the laser origin turned back by ``theta``). Only angles
within one step of a turntable angle of the scan count (all of them for a full turn).
"""

from __future__ import annotations

import numpy as np

from rangekit.geometry import invert_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.scene.raycast import _open3d_cast

__all__ = ["laser_visible_samples", "sheet_angles", "in_image"]


def sheet_angles(plane: np.ndarray, T_world_table: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(n, 2) turntable angles (radians, in [-pi, pi)) at which the points ``P`` (n, 3), world frame at table
    angle 0, lie on ``plane`` (4,) world ``n.X + d = 0``; NaN where the plane never reaches a point."""
    R, t = T_world_table[:3, :3], T_world_table[:3, 3]
    n_t = R.T @ plane[:3]
    d_t = float(plane[3] + plane[:3] @ t)
    p = (P - t) @ R
    A = n_t[0] * p[:, 0] + n_t[1] * p[:, 1]
    B = n_t[1] * p[:, 0] - n_t[0] * p[:, 1]
    C = n_t[2] * p[:, 2] + d_t
    r = np.hypot(A, B)
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.arccos(-C / r)
    phi = np.arctan2(B, A)
    out = np.stack([phi + half, phi - half], axis=1)
    return (out + np.pi) % (2 * np.pi) - np.pi


def in_image(camera, P: np.ndarray) -> np.ndarray:
    """(n,) bool: world points ``P`` (n, 3) in front of ``camera`` and inside its image."""
    z = (P - camera.T_world_cam[:3, 3]) @ camera.T_world_cam[:3, 2]
    uv = camera.project(P)
    return (z > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] < camera.width - 0.5) & \
        (uv[:, 1] >= -0.5) & (uv[:, 1] < camera.height - 0.5)


def _near_plan(theta: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(n,) bool: ``theta`` lies within one scan step of one of the scan's turntable ``angles``."""
    a = np.sort(np.asarray(angles, dtype=np.float64) % (2 * np.pi))
    step = float(np.median(np.diff(a))) if len(a) > 1 else 0.0
    t = theta % (2 * np.pi)
    i = np.searchsorted(a, t)
    lo, hi = a[(i - 1) % len(a)], a[i % len(a)]
    gap = np.minimum(np.abs((t - lo + np.pi) % (2 * np.pi) - np.pi), np.abs((hi - t + np.pi) % (2 * np.pi) - np.pi))
    return gap <= step + 1e-12


def _clear(from_obj: np.ndarray, P: np.ndarray, N: np.ndarray, V: np.ndarray, F: np.ndarray, eps: float,
           min_cos: float) -> np.ndarray:
    """(n,) bool: each ``P`` faces its own source point ``from_obj`` (n, 3) within ``min_cos`` and the first
    hit of the ray from the source towards it is the point itself."""
    to_c = from_obj - P
    dist = np.linalg.norm(to_c, axis=1)
    ok = np.einsum("ij,ij->i", N, to_c) > min_cos * dist
    idx = np.flatnonzero(ok)
    if idx.size:
        t, _ = _open3d_cast(V, F, from_obj[idx], -to_c[idx] / dist[idx, None])
        ok[idx] = t >= dist[idx] - eps
    return ok


def laser_visible_samples(world0, rig: Rig, angles, P: np.ndarray, N: np.ndarray, *, eps: float = 1e-5,
                          min_cos: float = 0.0) -> np.ndarray:
    """(n,) bool: which samples ``P`` (n, 3) with unit normals ``N``, world frame at table angle 0, some laser
    of ``rig`` lights where the camera sees them, at an angle of the scan. ``world0``: the scene's mesh at
    table angle 0 (occluders: the object and the table)."""
    T = rig.T_world_table
    seen = np.zeros(len(P), dtype=bool)
    for laser in rig.lasers:
        for theta in sheet_angles(np.asarray(laser.plane, dtype=np.float64), T, P).T:
            todo = np.flatnonzero(~seen & np.isfinite(theta))
            todo = todo[_near_plan(theta[todo], angles)]
            if todo.size == 0:
                continue
            M = _motions(T, theta[todo])
            X = np.einsum("nij,nj->ni", M[:, :3, :3], P[todo]) + M[:, :3, 3]
            todo = todo[in_image(rig.camera, X)]
            if todo.size == 0:
                continue
            M = _motions(T, theta[todo])
            Minv = np.linalg.inv(M)
            cam = np.einsum("nij,j->ni", Minv[:, :3, :3], rig.camera.center) + Minv[:, :3, 3]
            ok = _clear(cam, P[todo], N[todo], world0.vertices, world0.triangles, eps, min_cos)
            todo, Minv = todo[ok], Minv[ok]
            src = np.einsum("nij,j->ni", Minv[:, :3, :3], np.asarray(laser.origin, dtype=np.float64)) + Minv[:, :3, 3]
            ok = _clear(src, P[todo], N[todo], world0.vertices, world0.triangles, eps, min_cos)
            seen[todo[ok]] = True
    return seen


def _motions(T_world_table: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(n, 4, 4) ``table_motion(T_world_table, theta_i)`` for every angle at once."""
    c, s = np.cos(theta), np.sin(theta)
    Rz = np.zeros((len(theta), 4, 4))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = c, -s, s, c
    Rz[:, 2, 2] = Rz[:, 3, 3] = 1.0
    return T_world_table @ Rz @ invert_T(T_world_table)

