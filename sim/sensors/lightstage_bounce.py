"""One bounce of diffuse interreflection for the light stage (:mod:`rangekit.sim.sensors.lightstage`).

A concave object (the zoo's ``bowl``) lights itself: each surface point ``x`` seen by the camera also
receives the light its own walls reflect. The light stage adds the first bounce, Lambertian to
Lambertian, estimated by Monte Carlo with the same rays for every light::

    I_bounce_i(x) = gain * albedo(x) * (1/K) sum_k albedo(y_k) * E_i(y_k)

* ``y_k``: where the k-th of ``K`` cosine-weighted rays from ``x + eps * n(x)`` about the shading normal
  ``n(x)`` first meets the scene (front faces only; rays that escape bring nothing: no room light).
  With a cosine-weighted density ``cos / pi``, the mean of the reflected radiance ``albedo * E / pi``
  times ``pi`` is the irradiance it brings, so the estimate needs no other factor.
* ``E_i(y)``: the direct irradiance of light ``i`` at ``y``, ``s_i * falloff_i * max(n.l_i, 0)`` times its
  visibility (a shadow ray), computed at the vertices of the triangles hit and interpolated with the
  hit's barycentric coordinates (vertex normals, vertex albedo). Specular reflection from the walls
  and second and later bounces are left out.

The sample directions are drawn once per pixel from ``rng`` (a stratified cosine-weighted pattern,
randomly rotated per pixel), so the term is a smooth function of the light for each pixel, as real
interreflection is: it is a bias of the Lambertian model, not noise that averages out over lights.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse

from rangekit.sim.scene.raycast import WorldMesh, _intersect_exact, _open3d_cast

__all__ = ["one_bounce"]


def one_bounce(mesh: WorldMesh, T_cam_world: np.ndarray, x: np.ndarray, n: np.ndarray, lights: np.ndarray,
               kind: str, intensities: np.ndarray, ref_distance: float, *, samples: int = 32,
               rng: np.random.Generator, eps: float = 1e-4, colour: bool = False) -> np.ndarray:
    """(f, N, C) irradiance reflected onto ``x`` by its surroundings, times the albedo of what reflects it.

    Multiply by ``gain * albedo(x)`` for image intensity (module docstring).

    Parameters
    ----------
    mesh : the scene in the world frame.
    T_cam_world : (4, 4) world -> camera frame.
    x, n : (N, 3) camera-frame surface points (metres) and unit shading normals.
    lights : (f, 3) camera frame, unit directions towards the lights or positions (``kind="point"``).
    intensities : (f,) light intensities ``s_i``; ``ref_distance`` metres for the point lights' falloff.
    samples : rays per pixel K (>= 1).
    rng : Generator for the sample directions.
    colour : C = 3 (RGB vertex albedo) if True, else C = 1 (the channel mean).
    """
    R, t = T_cam_world[:3, :3], T_cam_world[:3, 3]
    V = mesh.vertices @ R.T + t
    Vn = mesh.vertex_normals @ R.T
    tri = mesh.triangles
    N, K = len(x), int(samples)

    # K stratified cosine-weighted directions per pixel in its tangent frame, rotated at random.
    j = np.arange(K)
    r = np.sqrt((j + 0.5) / K)
    phi = 2.399963229728653 * j                                   # golden angle: even spread
    phi = phi[None] + rng.uniform(0, 2 * np.pi, (N, 1))           # (N, K)
    local = np.stack([r[None] * np.cos(phi), r[None] * np.sin(phi),
                      np.broadcast_to(np.sqrt(1 - r * r)[None], (N, K))], axis=2)
    a = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    d = (local[..., :1] * t1[:, None] + local[..., 1:2] * t2[:, None] + local[..., 2:] * n[:, None]).reshape(-1, 3)
    o = np.repeat(x + eps * n, K, axis=0)
    center = V.mean(axis=0)  # Open3D is float32: cast near the origin
    _, prim = _open3d_cast(V - center, tri, o - center, d)
    hit = np.flatnonzero(prim >= 0)
    prim = prim[hit]
    e1 = V[tri[prim, 1]] - V[tri[prim, 0]]
    e2 = V[tri[prim, 2]] - V[tri[prim, 0]]
    front = np.einsum("ij,ij->i", np.cross(e1, e2), d[hit]) < 0   # outward triangles seen from outside
    hit, prim = hit[front], prim[front]
    _, b1, b2 = _intersect_exact(_Mesh(V, tri), prim, o[hit], d[hit])
    bary = np.clip(np.column_stack([1 - b1 - b2, b1, b2]), 0.0, 1.0)

    # Direct irradiance at the vertices those rays reach, per light (shadow rays included).
    verts, inv = np.unique(tri[prim], return_inverse=True)
    inv = inv.reshape(-1, 3)
    E = _vertex_irradiance(V - center, tri, V[verts] - center, Vn[verts], lights - (center if kind == "point" else 0),
                           kind, intensities, ref_distance, eps)     # (f, M)
    alb = mesh.vertex_albedo[verts] if colour else mesh.vertex_albedo[verts].mean(axis=1, keepdims=True)
    pix = np.repeat(hit // K, 3)
    A = scipy.sparse.csr_matrix((bary.ravel() / K, (pix, inv.ravel())), shape=(N, len(verts)))
    return np.stack([(A @ (E * alb[:, c][None]).T).T for c in range(alb.shape[1])], axis=2)


class _Mesh:
    """The two fields :func:`_intersect_exact` reads, in the camera frame."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray) -> None:
        self.vertices, self.triangles = vertices, triangles


def _vertex_irradiance(V: np.ndarray, tri: np.ndarray, p: np.ndarray, pn: np.ndarray, L: np.ndarray, kind: str,
                       s: np.ndarray, ref_distance: float, eps: float) -> np.ndarray:
    """(f, M) direct irradiance ``s * falloff * max(n.l, 0) * visible`` at points ``p`` with normals ``pn``."""
    f = len(L)
    if kind == "directional":
        l_dir = np.broadcast_to(L[:, None, :], (f, len(p), 3))
        dist = np.full((f, len(p)), np.inf)
        falloff = np.ones((f, len(p)))
    else:
        to = L[:, None, :] - p[None]
        dist = np.linalg.norm(to, axis=2)
        l_dir = to / dist[..., None]
        falloff = (ref_distance / dist) ** 2
    cos_i = np.einsum("fmk,mk->fm", l_dir, pn)
    fi, mi = np.nonzero(cos_i > 0)
    t_hit, _ = _open3d_cast(V, tri, p[mi] + eps * pn[mi], l_dir[fi, mi])
    E = np.zeros((f, len(p)))
    E[fi, mi] = np.where(t_hit < dist[fi, mi] - eps, 0.0, cos_i[fi, mi]) * s[fi] * falloff[fi, mi]
    return E
