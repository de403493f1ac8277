"""Ground truth of one camera view: what each pixel sees and where the projector lights it.

Open3D's ``RaycastingScene`` (float32, BVH) finds which triangle each ray hits; the hit point, depth
and barycentrics are then recomputed in float64 from that triangle (Moller-Trumbore), so the ground truth
is exact to double precision for the tessellated scene, not to float32 (~0.1 um at 0.5 m, 3e-4 px).

Frames: everything is in the rig's world frame, metres, unless the field says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.errors import SceneError
from rangekit.geometry import cross_rows, invert_T
from rangekit.sim.scene.scene_object import PlanarTexture
from rangekit.surface.raycast import query_scene, raycasting_scene

__all__ = ["WorldMesh", "ViewGeometry", "ViewCodes", "cast_view", "cast_codes", "pixel_corners"]


@dataclass(frozen=True, eq=False)
class WorldMesh:
    """All scene triangles in the world frame for one scene state (one turntable angle)."""

    vertices: np.ndarray        # (V, 3) float64 world, metres
    triangles: np.ndarray       # (F, 3) int64
    vertex_normals: np.ndarray  # (V, 3) float64 unit, world
    vertex_albedo: np.ndarray   # (V, 3) float64 linear RGB in [0, 1]
    face_specular: np.ndarray   # (F,) Blinn-Phong k_s
    face_shininess: np.ndarray  # (F,) Blinn-Phong exponent
    face_smooth: np.ndarray     # (F,) bool: shade with interpolated vertex normals
    face_object: np.ndarray     # (F,) int index into ``object_names``
    object_names: tuple[str, ...]
    object_poses: tuple[np.ndarray, ...] = ()  # per object (4, 4) T_world_obj at this state (after turntable motion)
    object_textures: tuple[PlanarTexture | None, ...] = ()  # per object, or () when no object is textured


@dataclass(frozen=True, eq=False)
class ViewGeometry:
    """Exact per-pixel ground truth of a camera view. All maps are (H, W[, 3]) in camera pixels.

    ``hit``: the camera ray meets a surface. ``lit``: additionally the projector lights that point
    (inside the projector image, facing the projector, no shadow). Undefined entries are NaN (floats),
    False (bools) or -1 (ints).
    """

    hit: np.ndarray         # (H, W) bool
    lit: np.ndarray         # (H, W) bool
    xyz: np.ndarray         # (H, W, 3) float64 world hit point, metres
    normal: np.ndarray      # (H, W, 3) float64 world unit shading normal, facing the camera
    depth: np.ndarray       # (H, W) float64 z of the hit in the camera frame, metres
    range: np.ndarray       # (H, W) float64 distance from the camera centre to the hit, metres
    proj_col: np.ndarray    # (H, W) float64 projector column u (pixel centres at integers); NaN unless lit
    proj_row: np.ndarray    # (H, W) float64 projector row v; NaN unless lit
    object_id: np.ndarray   # (H, W) int32 index into object_names, -1 where no hit
    object_names: tuple[str, ...]
    albedo: np.ndarray      # (H, W, 3) float64 linear RGB albedo, 0 where no hit
    cos_proj: np.ndarray    # (H, W) float64 cos(normal, direction to projector), 0 unless lit
    specular: np.ndarray    # (H, W) float64 k_s * (n.h)^shininess towards projector and camera, 0 unless lit
    proj_dist: np.ndarray   # (H, W) float64 distance hit -> projector centre, metres; NaN where no hit

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: seen by the camera and lit by the projector (where projector codes exist)."""
        return self.lit


def _open3d_cast(vertices: np.ndarray, triangles: np.ndarray, origins: np.ndarray,
                 directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each ray: (t_hit float32 with inf for misses, primitive id int64 with -1 for misses)."""
    return _cast(raycasting_scene(vertices, triangles), origins, directions)


def _cast(scene, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`_open3d_cast` on a scene already built (:func:`rangekit.surface.raycast.raycasting_scene`)."""
    rays = np.empty((len(directions), 6), np.float32)   # filled in place: no (N, 6) float64 copy on the way
    rays[:, :3], rays[:, 3:] = origins, directions
    out = query_scene(scene, "cast_rays", rays)
    t_hit = out["t_hit"]
    prim = out["primitive_ids"].astype(np.int64)
    prim[~np.isfinite(t_hit)] = -1
    return t_hit, prim


def _intersect_exact(mesh: WorldMesh, prim: np.ndarray, o: np.ndarray, d: np.ndarray):
    """Float64 Moller-Trumbore against the given triangles: (t, b1, b2)."""
    tri = mesh.triangles[prim]
    v0 = mesh.vertices[tri[:, 0]]
    e1 = mesh.vertices[tri[:, 1]] - v0
    e2 = mesh.vertices[tri[:, 2]] - v0
    pvec = cross_rows(d, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    tvec = o - v0
    b1 = np.einsum("ij,ij->i", tvec, pvec) / det
    qvec = cross_rows(tvec, e1)
    b2 = np.einsum("ij,ij->i", d, qvec) / det
    t = np.einsum("ij,ij->i", e2, qvec) / det
    return t, b1, b2


def pixel_corners(camera: PinholeCamera) -> np.ndarray:
    """((H + 1) * (W + 1), 2) float64 pixel corners, row-major: corner ``i * (W + 1) + j`` is
    ``(u, v) = (j - 0.5, i - 0.5)``, the top-left corner of pixel (j, i)."""
    v, u = np.mgrid[0: camera.height + 1, 0: camera.width + 1]
    return np.column_stack([u.ravel(), v.ravel()]).astype(np.float64) - 0.5


def _texture_albedo(tex: PlanarTexture, T_world_obj: np.ndarray, p: np.ndarray, pix: np.ndarray,
                    camera: PinholeCamera, corner_rays) -> np.ndarray:
    """(N,) texture albedo box-filtered over each pixel's footprint; NaN where the hit is not on the
    textured part of the object's z = 0 plane (the vertex albedo stays there).

    The footprint is the object-frame bounding box of the four pixel-corner rays (lens distortion
    included) meeting the plane; the texture is averaged over it exactly (area sampling). The corner
    rays are intersected once per corner, over the corner grid's box around the textured pixels.
    """
    T_obj_world = invert_T(T_world_obj)
    R, t = T_obj_world[:3, :3], T_obj_world[:3, 3]
    p_obj = p @ R.T + t
    x0, y0, x1, y1 = tex.extent
    on = (np.abs(p_obj[:, 2]) <= 1e-6) & (p_obj[:, 0] >= x0) & (p_obj[:, 0] <= x1) & \
        (p_obj[:, 1] >= y0) & (p_obj[:, 1] <= y1)
    out = np.full(len(p), np.nan)
    sel = np.flatnonzero(on)
    if sel.size == 0:
        return out
    v, u = np.divmod(pix[sel], camera.width)
    r0, r1, c0, c1 = v.min(), v.max() + 2, u.min(), u.max() + 2  # corner rows/cols [r0, r1) x [c0, c1)
    if corner_rays is not None:
        d = corner_rays[1].reshape(camera.height + 1, camera.width + 1, 3)[r0:r1, c0:c1].reshape(-1, 3)
    else:
        cv, cu = np.mgrid[r0:r1, c0:c1]
        d = camera.rays(np.column_stack([cu.ravel(), cv.ravel()]).astype(np.float64) - 0.5)[1]
    o = R @ camera.center + t
    d = d @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -o[2] / d[:, 2]
        s[~(s > 0)] = np.nan  # the corner ray misses the plane (grazing view)
        X = (o[0] + s * d[:, 0]).reshape(r1 - r0, c1 - c0)
        Y = (o[1] + s * d[:, 1]).reshape(r1 - r0, c1 - c0)
    lo_hi = []
    for G in (X, Y):
        quad = (G[:-1, :-1], G[:-1, 1:], G[1:, :-1], G[1:, 1:])
        lo = np.fmin(np.fmin(quad[0], quad[1]), np.fmin(quad[2], quad[3]))
        hi = np.fmax(np.fmax(quad[0], quad[1]), np.fmax(quad[2], quad[3]))
        k = (v - r0) * (c1 - c0 - 1) + (u - c0)
        lo_hi.append((np.take(lo, k), np.take(hi, k)))
    (xl, xh), (yl, yh) = lo_hi
    bad = ~(np.isfinite(xl) & np.isfinite(yl))  # every corner missed: sample the texel under the centre
    if np.any(bad):
        xl[bad], xh[bad] = p_obj[sel[bad], 0], p_obj[sel[bad], 0]
        yl[bad], yh[bad] = p_obj[sel[bad], 1], p_obj[sel[bad], 1]
    out[sel] = tex.box_mean(xl, yl, xh, yh)
    return out


def cast_view(mesh: WorldMesh, camera: PinholeCamera, projector: PinholeCamera | None, *,
              cam_rays: tuple[np.ndarray, np.ndarray] | None = None,
              corner_rays: tuple[np.ndarray, np.ndarray] | None = None,
              shadow_eps: float = 2e-5, pixels: np.ndarray | None = None) -> ViewGeometry:
    """Cast every camera pixel into the scene and trace its shadow ray to the projector.

    Albedo: the vertex albedo interpolated at the hit, except on the front side of an object's
    :class:`~rangekit.sim.scene.objects.PlanarTexture`, where it is the texture **area-sampled** over the
    pixel: the rays through the pixel's four corners (lens distortion included) meet the object's
    z = 0 plane, and the texture is averaged exactly (summed-area table, partial texels by area) over
    the bounding box of those four points. A pixel straddling a square edge thus gets the
    area-weighted albedo of both sides (exact for a fronto-parallel plane and no distortion, where the
    footprint is the box). Only textured pixels pay for this.

    Parameters
    ----------
    mesh : WorldMesh of the scene at this state.
    camera : the camera; every pixel centre is cast.
    projector : the projector, or None for a scene without one (``lit`` is then all False).
    cam_rays : optional cached :func:`rangekit.camera.world_pixel_rays` (they do not change between views).
    corner_rays : optional cached ``camera.rays(pixel_corners(camera))`` for textured objects; without it
        only the corners of textured pixels are back-projected.
    shadow_eps : float
        Metres: an occluder must be at least this much closer to the projector than the point to shadow it.
    pixels : optional (K,) flat pixel indices (row * W + column) to cast; the maps hold nothing (as where
        nothing is hit) at the other pixels. Default every pixel.

    Raises
    ------
    SceneError
        If the mesh is empty or no camera ray hits any surface.
    """
    H, W = camera.height, camera.width
    scene = _scene_of(mesh)   # one BVH for the camera and the shadow rays
    hits = _camera_hits(mesh, camera, scene, cam_rays, pixels)
    hit_idx, prim, d, t, p, tri, wb, n_face, n, back = (hits.hit_idx, hits.prim, hits.d, hits.t, hits.p, hits.tri,
                                                        hits.wb, hits.n_face, hits.n, hits.back)
    albedo = np.einsum("ij,ijk->ik", wb, mesh.vertex_albedo[tri])
    owner = hits.owner
    for k, tex in enumerate(mesh.object_textures):
        if tex is None:
            continue
        sel = np.flatnonzero((owner == k) & ~back)  # the printed (front) side only
        if sel.size:
            value = _texture_albedo(tex, mesh.object_poses[k], p[sel], hit_idx[sel], camera, corner_rays)
            ok = np.isfinite(value)
            albedo[sel[ok]] = value[ok, None]

    def full(shape, fill, dtype=np.float64):
        return np.full((H * W,) + shape, fill, dtype=dtype)

    xyz, normal, alb = full((3,), np.nan), full((3,), np.nan), full((3,), 0.0)
    xyz[hit_idx], normal[hit_idx], alb[hit_idx] = p, n, albedo
    depth, rng_map = full((), np.nan), full((), np.nan)
    depth[hit_idx], rng_map[hit_idx] = hits.cam_z, t
    obj = full((), -1, np.int32)
    obj[hit_idx] = owner
    proj_col, proj_row = full((), np.nan), full((), np.nan)
    cos_proj, spec, pdist = full((), 0.0), full((), 0.0), full((), np.nan)
    lit = np.zeros(H * W, dtype=bool)

    if projector is not None:
        light = _projector_light(scene, projector, hits, shadow_eps)
        ok, uvp, l_dir = light.ok, light.uvp, light.l_dir
        pdist[hit_idx] = light.dist_p
        lit_idx = hit_idx[ok]
        lit[lit_idx] = True
        proj_col[lit_idx] = uvp[ok, 0]
        proj_row[lit_idx] = uvp[ok, 1]
        cos_proj[lit_idx] = light.cos_i[ok]
        # Blinn-Phong half vector between the projector and the camera directions.
        v_dir = -d[ok]
        h = l_dir[ok] + v_dir
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ks = mesh.face_specular[prim[ok]]
        if np.any(ks > 0):
            nh = np.clip(np.einsum("ij,ij->i", n[ok], h), 0.0, 1.0)
            spec[lit_idx] = ks * nh ** mesh.face_shininess[prim[ok]]

    return ViewGeometry(
        hit=(obj >= 0).reshape(H, W), lit=lit.reshape(H, W), xyz=xyz.reshape(H, W, 3),
        normal=normal.reshape(H, W, 3), depth=depth.reshape(H, W), range=rng_map.reshape(H, W),
        proj_col=proj_col.reshape(H, W), proj_row=proj_row.reshape(H, W), object_id=obj.reshape(H, W),
        object_names=mesh.object_names, albedo=alb.reshape(H, W, 3), cos_proj=cos_proj.reshape(H, W),
        specular=spec.reshape(H, W), proj_dist=pdist.reshape(H, W))


def _scene_of(mesh: WorldMesh):
    """Open3D's ray-casting scene of ``mesh``; SceneError when it has no triangle."""
    if len(mesh.triangles) == 0:
        raise SceneError("the scene has no triangles; add at least one object")
    return raycasting_scene(mesh.vertices, mesh.triangles)


@dataclass(frozen=True, eq=False)
class _Hits:
    """The camera rays that hit something (K of them): flat pixel index ``hit_idx`` (K,), triangle ``prim`` (K,),
    ray ``o``, ``d`` (K, 3), float64 ``t`` and point ``p`` (K, 3), the triangle's vertex indices ``tri`` (K, 3),
    clipped barycentric weights ``wb`` (K, 3), unit face and shading normals ``n_face``, ``n`` (K, 3) facing the
    camera, ``back`` (K,) the back side was hit, ``owner`` (K,) object index, ``cam_z`` (K,) camera-frame depth."""

    hit_idx: np.ndarray
    prim: np.ndarray
    o: np.ndarray
    d: np.ndarray
    t: np.ndarray
    p: np.ndarray
    tri: np.ndarray
    wb: np.ndarray
    n_face: np.ndarray
    n: np.ndarray
    back: np.ndarray
    owner: np.ndarray
    cam_z: np.ndarray


def _camera_hits(mesh: WorldMesh, camera: PinholeCamera, scene, cam_rays, pixels) -> _Hits:
    """Every camera pixel's ray (or those of ``pixels``) cast into ``scene`` (``mesh``'s), the hits recomputed in
    float64 (see :func:`cast_view`); SceneError when nothing is hit."""
    H, W = camera.height, camera.width
    o_all, d_all = cam_rays if cam_rays is not None else world_pixel_rays(camera)
    if pixels is None:
        _, prim_all = _cast(scene, o_all, d_all)
        hit_idx = np.flatnonzero(prim_all >= 0)
    else:
        pixels = np.asarray(pixels, dtype=np.int64)
        _, prim_sub = _cast(scene, o_all[pixels], d_all[pixels])
        hit_idx = pixels[prim_sub >= 0]
        prim_all = np.full(H * W, -1, np.int64)
        prim_all[hit_idx] = prim_sub[prim_sub >= 0]
    if hit_idx.size == 0:
        raise SceneError(f"camera {camera.name!r} sees nothing: none of its {H * W} rays hits the scene "
                         f"(objects: {', '.join(mesh.object_names)}); check T_world_cam and where the objects "
                         "are placed")
    prim = prim_all[hit_idx]
    o, d = o_all[hit_idx], d_all[hit_idx]
    t, b1, b2 = _intersect_exact(mesh, prim, o, d)
    p = o + t[:, None] * d
    tri = mesh.triangles[prim]
    v0 = mesh.vertices[tri[:, 0]]
    n_face = cross_rows(mesh.vertices[tri[:, 1]] - v0, mesh.vertices[tri[:, 2]] - v0)
    n_face /= np.linalg.norm(n_face, axis=1, keepdims=True)
    # Barycentric weights, clipped for attribute interpolation (float32 may pick an edge neighbour).
    wb = np.column_stack([1.0 - b1 - b2, b1, b2]).clip(0.0, 1.0)
    wb /= wb.sum(axis=1, keepdims=True)
    n_smooth = np.einsum("ij,ijk->ik", wb, mesh.vertex_normals[tri])
    n_smooth /= np.linalg.norm(n_smooth, axis=1, keepdims=True)
    smooth = mesh.face_smooth[prim]
    n = np.where(smooth[:, None], n_smooth, n_face)
    # Face the camera: a surface seen from its back side is shaded as its front.
    back = np.einsum("ij,ij->i", n_face, d) > 0
    n_face[back] *= -1
    n[back] *= -1
    cam_z = (p - camera.center) @ camera.T_world_cam[:3, 2]
    return _Hits(hit_idx, prim, o, d, t, p, tri, wb, n_face, n, back, mesh.face_object[prim], cam_z)


@dataclass(frozen=True, eq=False)
class _Light:
    """The projector's light on :class:`_Hits` (K of them): ``ok`` the indices into the hits it lights (inside its
    image, facing it, no shadow), ``uvp`` (K, 2) projector pixels, ``l_dir`` (K, 3) unit directions to it,
    ``dist_p`` (K,) distances to its centre, ``cos_i`` (K,) cosine of the shading normal with ``l_dir``."""

    ok: np.ndarray
    uvp: np.ndarray
    l_dir: np.ndarray
    dist_p: np.ndarray
    cos_i: np.ndarray


def _projector_light(scene, projector: PinholeCamera, hits: _Hits, shadow_eps: float) -> _Light:
    """Which hits ``projector`` lights: inside its image, facing it, and no triangle of ``scene`` more than
    ``shadow_eps`` metres closer to it along the shadow ray."""
    return _light_on(scene, projector, hits.p, hits.n, hits.n_face, hits.prim, shadow_eps)


def _light_on(scene, projector: PinholeCamera, p: np.ndarray, n: np.ndarray, n_face: np.ndarray, prim: np.ndarray,
              shadow_eps: float) -> _Light:
    """:func:`_projector_light` of the hits ``p`` (K, 3) with shading and face normals ``n``, ``n_face`` (K, 3) on
    triangles ``prim`` (K,): each hit's answer its own (the same bits for any subset of the hits)."""
    c_p = projector.center
    to_p = c_p - p
    dist_p = np.linalg.norm(to_p, axis=1)
    l_dir = to_p / dist_p[:, None]
    uvp = projector.project(p)
    inside = (uvp[:, 0] >= -0.5) & (uvp[:, 0] < projector.width - 0.5) & \
             (uvp[:, 1] >= -0.5) & (uvp[:, 1] < projector.height - 0.5)
    cos_i = np.einsum("ij,ij->i", n, l_dir)
    facing = (np.einsum("ij,ij->i", n_face, l_dir) > 0) & (cos_i > 0)
    cand = np.flatnonzero(inside & facing)
    # Shadow rays from the projector centre towards each candidate point.
    t_s, prim_s = _cast(scene, np.broadcast_to(c_p, (cand.size, 3)), -l_dir[cand])
    blocked = (prim_s != prim[cand]) & (t_s < dist_p[cand] - shadow_eps)
    return _Light(cand[~blocked], uvp, l_dir, dist_p, cos_i)


@dataclass(frozen=True, eq=False)
class ViewCodes:
    """The geometric part of :class:`ViewGeometry` (the same values), for a caller that needs no shading:
    ``depth`` (H, W) float64 camera-frame z, metres, NaN where nothing is hit; ``proj_col`` (H, W) float64
    projector column, NaN unless lit; ``object_id`` (H, W) int32, -1 where nothing is hit."""

    depth: np.ndarray
    proj_col: np.ndarray
    object_id: np.ndarray


def cast_codes(mesh: WorldMesh, camera: PinholeCamera, projector: PinholeCamera | None, *,
               cam_rays: tuple[np.ndarray, np.ndarray] | None = None, shadow_eps: float = 2e-5,
               pixels: np.ndarray | None = None, light_at: np.ndarray | None = None,
               light_object: int | None = None) -> ViewCodes:
    """:func:`cast_view`'s depth, projector column and object maps (the same bits) without its shading (albedo,
    textures, normals, specular, the other maps): the truth a decoding is measured against, at about 2/3 of
    the cost. Arguments and errors as :func:`cast_view`; ``pixels`` as there (the maps hold nothing at the other
    pixels). The projector's light is traced only where asked: ``light_at`` (H * W,) bool, the pixels whose
    hits it is traced for, and ``light_object``, only on that object's hits (index into ``mesh.object_names``);
    ``proj_col`` is NaN at the other hits. Every pixel's values are its own ray's: the same bits whichever
    other pixels are cast or lit."""
    H, W = camera.height, camera.width
    scene = _scene_of(mesh)
    hits = _camera_hits(mesh, camera, scene, cam_rays, pixels)
    depth = np.full(H * W, np.nan)
    depth[hits.hit_idx] = hits.cam_z
    obj = np.full(H * W, -1, np.int32)
    obj[hits.hit_idx] = hits.owner
    proj_col = np.full(H * W, np.nan)
    if projector is not None:
        wanted = np.ones(len(hits.hit_idx), dtype=bool)
        if light_at is not None:
            wanted &= np.asarray(light_at, dtype=bool).reshape(-1)[hits.hit_idx]
        if light_object is not None:
            wanted &= hits.owner == light_object
        if wanted.all():
            light = _projector_light(scene, projector, hits, shadow_eps)
            proj_col[hits.hit_idx[light.ok]] = light.uvp[light.ok, 0]
        else:
            some = np.flatnonzero(wanted)
            light = _light_on(scene, projector, hits.p[some], hits.n[some], hits.n_face[some], hits.prim[some],
                              shadow_eps)
            proj_col[hits.hit_idx[some[light.ok]]] = light.uvp[light.ok, 0]
    return ViewCodes(depth.reshape(H, W), proj_col.reshape(H, W), obj.reshape(H, W))
