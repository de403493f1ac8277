"""A simulated photometric-stereo light stage: one fixed camera, f lights switched on one at a time.

The camera ray casting (:func:`rangekit.sim.scene.raycast.cast_view` without a projector) is done once; each
light then costs a vectorised shading pass. For each pixel that sees a surface and each light ``i``::

    E_i = gain * s_i * [albedo * max(n.l_i, 0) + k_s (n.h_i)^shininess] * falloff_i + gain * ambient * albedo

* ``l_i``: unit direction from the surface point towards the light. Directional lights give it directly
  (``falloff = 1``); point lights give a position ``P_i`` and ``l_i = (P_i - x) / |P_i - x|`` per pixel
  with ``falloff = (ref_distance / |P_i - x|)^2`` (``ImagingModel.ref_distance``).
* ``s_i``: the light's intensity (1 unless given). ``h_i``: Blinn-Phong half vector of ``l_i`` and the
  direction to the camera; ``k_s``, ``shininess`` come from each object's :class:`SceneObject` fields.
* Attached shadow: ``n.l_i <= 0`` (shading normal). Cast shadow: a ray from ``x + shadow_eps * n``
  towards the light hits any triangle (before the light, for point lights); the light term is then 0.
* Interreflection (``bounce_samples > 0``): one diffuse bounce, ``gain * albedo * (1/K) sum_k albedo(y_k)
  E_i(y_k)`` over K cosine-weighted rays per pixel (:mod:`rangekit.sim.sensors.lightstage_bounce`): a concave
  object lights itself; on a convex one the rays escape and the term is 0.
* Then, as in :mod:`rangekit.sim.imaging.render`: camera lens blur (``camera_blur``), shot + read noise
  (:meth:`ImagingModel.noise_std`), clipping and quantisation to ``bits``. The projector-only fields
  (gamma, black_level, projector_blur, global_fraction, global_blur) do not apply.

Frames: lights, normals and depth are in the OpenCV camera frame (x right, y down, z forward). A light
on the camera's side of the object has a negative z component.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import make_T
from rangekit.sim.scene.objects import make_object
from rangekit.sim.sensors.lightstage_bounce import one_bounce
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.imaging.render import ImagingModel
from rangekit.sim.scene.scene import Scene
from rangekit.surface.raycast import query_scene, raycasting_scene

__all__ = ["LightStageCapture", "LIGHT_STAGE_MODEL", "PLATE_OBJECTS", "light_stage_camera", "light_stage_lights",
           "light_stage_scene", "render_light_stage"]

#: Default sensor of the light stage: 16-bit like DiLiGenT, no room light, otherwise ImagingModel's defaults.
LIGHT_STAGE_MODEL = ImagingModel(bits=16, ambient=0.0)


@dataclass(frozen=True, eq=False, repr=False)
class LightStageCapture:
    """Images of a light stage and the exact truth, all in the camera frame.

    images : (f, H, W) float32 (or (f, H, W, 3) for a colour model) in [0, 1]: quantised digital numbers
        divided by ``2**bits - 1``; linear in irradiance.
    lights : (f, 3) float64, camera frame: unit directions towards each light (``kind="directional"``) or
        light positions in metres (``kind="point"``).
    intensities : (f,) float64 light intensities ``s_i``.
    kind : "directional" or "point".
    normals_true : (H, W, 3) float64 unit shading normals, camera frame, facing the camera (z < 0); NaN
        outside ``mask``.
    albedo_true : (H, W) float64 Lambertian albedo (mean of RGB, what a mono sensor sees); NaN outside.
    depth_true : (H, W) float64 camera z of the surface, metres; NaN outside.
    mask : (H, W) bool, pixels that see a surface.
    shadowed : (f, H, W) bool, mask pixels with no direct light from light i (attached or cast shadow).
    cast_shadow : (f, H, W) bool, the cast part of ``shadowed`` (facing the light but occluded).
    camera : the camera (its ``T_world_cam`` relates the camera frame to the scene's world frame).
    """

    images: np.ndarray
    lights: np.ndarray
    intensities: np.ndarray
    kind: str
    normals_true: np.ndarray
    albedo_true: np.ndarray
    depth_true: np.ndarray
    mask: np.ndarray
    shadowed: np.ndarray
    cast_shadow: np.ndarray
    camera: PinholeCamera

    def __repr__(self) -> str:
        f, H, W = self.images.shape[:3]
        return (f"LightStageCapture({f} {self.kind} lights, {W}x{H}, mask_pixels={int(self.mask.sum())}, "
                f"shadowed_fraction={self.shadowed[:, self.mask].mean():.3f})")


def light_stage_camera(width: int = 320, height: int = 256) -> PinholeCamera:
    """The simulator's camera lens (:func:`rangekit.sim.devices.sim_rig.default_rig`) on a ``width`` x ``height``
    sensor (same field of view), posed at the world origin (``T_world_cam`` = identity: world = camera)."""
    from rangekit.sim.devices.sim_rig import default_rig

    return default_rig().cameras[0].resized(width, height).with_pose(np.eye(4))


def light_stage_lights(n: int = 96, *, min_angle: float = np.radians(5.0), max_angle: float = np.radians(45.0),
                       rng: int | np.random.Generator = 0) -> np.ndarray:
    """(n, 3) float64 unit light directions, camera frame, spread uniformly over a cap facing the object.

    Directions point from the object towards the lights, which stand on the camera's side: each makes
    an angle in ``[min_angle, max_angle]`` radians with the camera's backward axis (0, 0, -1) (DiLiGenT's
    ball: 4 to 43 deg), uniform in solid angle, azimuth uniform; drawn from ``rng``.
    """
    if int(n) != n or n < 1:
        raise InputError(f"light_stage_lights: n must be an integer >= 1, found {n!r}")
    if not (0.0 <= min_angle <= max_angle < np.pi / 2):
        raise InputError(f"light_stage_lights: need 0 <= min_angle <= max_angle < pi/2 radians, found "
                         f"min_angle={min_angle!r}, max_angle={max_angle!r}")
    rng = np.random.default_rng(rng)
    cos_t = rng.uniform(np.cos(max_angle), np.cos(min_angle), int(n))
    phi = rng.uniform(0.0, 2 * np.pi, int(n))
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    return np.column_stack([sin_t * np.cos(phi), sin_t * np.sin(phi), -cos_t])


#: Objects built standing on the turntable plate (lowest point at z = 0, z up): the light stage turns their
#: up axis towards the camera, so it looks into the bowl and down on the steps, the fins and the bunny.
PLATE_OBJECTS = ("bowl", "thin", "steps", "bunny")


def light_stage_scene(obj: str = "sphere", *, distance: float = 0.5, occluder: bool = False,
                      face_camera: bool | None = None, **object_options) -> Scene:
    """A scene for :func:`light_stage_camera`: ``obj`` (builtin name) centred ``distance`` metres in
    front of the camera (world = camera frame), nothing behind it.

    ``face_camera`` turns the object's up axis (+z) towards the camera (a half turn about x) and puts
    the centre of its bounding box on the optical axis; default: True for :data:`PLATE_OBJECTS` (the
    camera then looks into the ``bowl``), False otherwise (the object's origin goes to the axis).

    ``occluder=True`` adds a box (4 x 12 x 20 cm along x, y, z; albedo 0.5) beside it, centred at
    x = +0.1 m, out of the camera's line of sight to a 5 cm sphere: a light from the +x side (e.g.
    direction (0.97, 0, -0.24)) casts its shadow on the object's right side.
    """
    o = make_object(obj, **object_options)
    T = make_T(t=[0.0, 0.0, distance])
    if obj in PLATE_OBJECTS if face_camera is None else face_camera:
        R = np.diag([1.0, -1.0, -1.0])
        T = make_T(R, [0.0, 0.0, distance] - R @ (o.vertices.min(axis=0) + o.vertices.max(axis=0)) / 2)
    objects = [o.with_pose(T)]
    if occluder:
        objects.append(make_object("box", extents=(0.04, 0.12, 0.2), albedo=0.5)
                       .with_pose(make_T(t=[0.1, 0.0, distance])))
    return Scene(tuple(objects))


def render_light_stage(scene: Scene, lights: np.ndarray, *, camera: PinholeCamera | None = None,
                       kind: str = "directional", intensities: np.ndarray | None = None,
                       model: ImagingModel = LIGHT_STAGE_MODEL, rng: int | np.random.Generator = 0,
                       specular: bool = True, shadows: bool = True, shadow_eps: float = 1e-4,
                       bounce_samples: int = 32) -> LightStageCapture:
    """Render one image per light, and the truth, for a fixed camera.

    Parameters
    ----------
    scene : the objects, in the world frame of ``camera.T_world_cam``.
    lights : (f, 3) camera frame: unit directions towards the lights, or light positions in metres.
    camera : the camera; default :func:`light_stage_camera` (320 x 256, world = camera frame).
    kind : {"directional", "point"}
    intensities : (f,) light intensities ``s_i`` >= 0; default all 1.
    model : sensor model (gain, ambient, camera blur, noise, bits, colour; see the module docstring).
    rng : seed or Generator for the noise; the same seed gives the same images.
    specular : add each object's Blinn-Phong term (False: purely Lambertian).
    shadows : cast shadow rays (False: only attached shadows, ``n.l <= 0``).
    shadow_eps : metres; shadow rays start this far off the surface along the normal.
    bounce_samples : rays per pixel for the one-bounce interreflection; 0 leaves it out.

    Returns
    -------
    LightStageCapture

    Raises
    ------
    InputError
        If ``lights`` is not (f, 3) finite, directional lights are not unit length, ``kind`` is unknown
        or ``intensities`` does not match. :class:`SceneError` if the camera sees nothing.
    """
    L, s = _checked_lights(lights, kind, intensities, bounce_samples)
    f = len(L)
    camera = light_stage_camera() if camera is None else camera
    rng = np.random.default_rng(rng)
    H, W = camera.height, camera.width
    srf = _seen_surface(scene, camera, specular)
    l_dir, falloff, cos_i, lit, cast = _light_paths(srf, L, kind, model.ref_distance, camera.T_world_cam, shadows,
                                                    shadow_eps)
    spec = _blinn_phong(srf, l_dir)
    C = 3 if model.colour else 1
    alb_c = srf.albedo if model.colour else srf.albedo.mean(axis=1, keepdims=True)  # (N, C)
    direct = (alb_c[None] * np.where(lit, cos_i, 0.0)[..., None] + np.where(lit, spec, 0.0)[..., None]) \
        * (model.gain * s[:, None] * falloff)[..., None]    # (f, N, C)
    if bounce_samples > 0:
        direct += model.gain * alb_c[None] * one_bounce(
            srf.mesh, camera.T_cam_world, srf.x, srf.n, L, kind, s, model.ref_distance, samples=int(bounce_samples),
            rng=rng.spawn(1)[0], eps=shadow_eps, colour=model.colour)
    img = np.zeros((f, H * W, C), np.float32)
    img[:, srf.idx] = direct + model.gain * model.ambient * alb_c[None]
    img = _exposed(img.reshape(f, H, W, C), model, rng)
    idx = srf.idx
    return LightStageCapture(
        images=img if model.colour else img[..., 0], lights=L.copy(), intensities=s, kind=kind,
        normals_true=_per_pixel(srf.n, idx, (H, W), np.nan, (3,)),
        albedo_true=_per_pixel(srf.albedo.mean(axis=1), idx, (H, W), np.nan),
        depth_true=_per_pixel(srf.x[:, 2], idx, (H, W), np.nan), mask=srf.hit.copy(),
        shadowed=_per_light(~lit, idx, (H, W)), cast_shadow=_per_light(cast, idx, (H, W)), camera=camera)


def _checked_lights(lights, kind: str, intensities, bounce_samples) -> tuple[np.ndarray, np.ndarray]:
    """``(L, s)``: the lights as a finite (f, 3) float64 array (unit directions for ``kind`` "directional") and
    their (f,) intensities (default 1); InputError naming what is wrong, ``kind`` and ``bounce_samples`` too."""
    if kind not in ("directional", "point"):
        raise InputError(f"render_light_stage: kind must be 'directional' or 'point', found {kind!r}")
    L = np.asarray(lights, dtype=np.float64)
    if L.ndim != 2 or L.shape[1] != 3 or len(L) < 1 or not np.all(np.isfinite(L)):
        raise InputError(f"render_light_stage: lights must be a finite (f, 3) array, found shape {L.shape}")
    if kind == "directional" and not np.allclose(np.linalg.norm(L, axis=1), 1.0, atol=1e-6):
        raise InputError("render_light_stage: directional lights must be unit vectors (camera frame, towards "
                         f"the light); lengths range {np.linalg.norm(L, axis=1).min():.6g} to "
                         f"{np.linalg.norm(L, axis=1).max():.6g}")
    f = len(L)
    s = np.ones(f) if intensities is None else np.asarray(intensities, dtype=np.float64).reshape(-1)
    if s.shape != (f,) or not np.all(np.isfinite(s) & (s >= 0)):
        raise InputError(f"render_light_stage: intensities must be {f} finite values >= 0, found shape {s.shape}")
    if int(bounce_samples) != bounce_samples or not 0 <= bounce_samples <= 4096:
        raise InputError(f"render_light_stage: bounce_samples must be an integer in 0..4096, found {bounce_samples!r}")
    return L, s


@dataclass(frozen=True, eq=False)
class _SeenSurface:
    """What the camera sees, cast once for every light: the world ``mesh``, the (H, W) bool ``hit`` map and, for
    its N hit pixels (flat indices ``idx`` (N,) into H * W), the points ``x`` (N, 3) metres and unit normals ``n``
    (N, 3) facing the camera, both in the camera frame, ``albedo`` (N, 3), specular weight ``ks`` and ``shininess``
    (N,) of each pixel's object."""

    mesh: object
    hit: np.ndarray
    idx: np.ndarray
    x: np.ndarray
    n: np.ndarray
    albedo: np.ndarray
    ks: np.ndarray
    shininess: np.ndarray


def _seen_surface(scene: Scene, camera: PinholeCamera, specular: bool) -> _SeenSurface:
    """The scene as ``camera`` sees it (:class:`_SeenSurface`); ``specular`` False: every ``ks`` 0."""
    mesh = scene.world_mesh()
    g = cast_view(mesh, camera, None)
    idx = np.flatnonzero(g.hit.ravel())
    R_cw, t_cw = camera.T_cam_world[:3, :3], camera.T_cam_world[:3, 3]
    obj = g.object_id.ravel()[idx]
    return _SeenSurface(mesh=mesh, hit=g.hit, idx=idx, x=g.xyz.reshape(-1, 3)[idx] @ R_cw.T + t_cw,
                        n=g.normal.reshape(-1, 3)[idx] @ R_cw.T, albedo=g.albedo.reshape(-1, 3)[idx],
                        ks=np.array([o.specular for o in scene.objects])[obj] if specular else np.zeros(len(idx)),
                        shininess=np.array([o.shininess for o in scene.objects])[obj])


def _light_paths(srf: _SeenSurface, L: np.ndarray, kind: str, ref_distance: float, T_world_cam: np.ndarray,
                 shadows: bool, shadow_eps: float) -> tuple[np.ndarray, ...]:
    """Per light and seen pixel, the path to the light (camera frame): ``l_dir`` (f, N, 3) unit directions towards
    it, ``falloff`` (f, N) (1 for directional lights, ``(ref_distance / distance) ** 2`` for point lights),
    ``cos_i`` (f, N) = n . l, ``lit`` (f, N) bool (neither attached nor, with ``shadows``, cast shadow) and
    ``cast`` (f, N) bool (a triangle between the point and the light)."""
    f, N = len(L), len(srf.idx)
    if kind == "directional":
        l_dir = np.broadcast_to(L[:, None, :], (f, N, 3))
        dist = np.full((f, N), np.inf)
        falloff = np.ones((f, N))
    else:
        to = L[:, None, :] - srf.x[None]                    # (f, N, 3)
        dist = np.linalg.norm(to, axis=2)
        l_dir = to / dist[..., None]
        falloff = (ref_distance / dist) ** 2
    cos_i = np.einsum("fnk,nk->fn", l_dir, srf.n)
    lit = cos_i > 0
    cast = np.zeros_like(lit)
    if shadows:
        cast = lit & _occluded(srf.mesh.vertices, srf.mesh.triangles, T_world_cam, srf.x, srf.n, l_dir, dist, lit,
                               shadow_eps)
        lit &= ~cast
    return l_dir, falloff, cos_i, lit, cast


def _blinn_phong(srf: _SeenSurface, l_dir: np.ndarray) -> np.ndarray:
    """(f, N) the specular term ``ks (n . h) ** shininess``, ``h`` the half vector between the light ``l_dir``
    (f, N, 3) and the camera (at the origin of the camera frame); zeros where no object is specular."""
    v = -srf.x / np.linalg.norm(srf.x, axis=1, keepdims=True)
    if not np.any(srf.ks > 0):
        return np.zeros(l_dir.shape[:2])
    h = l_dir + v[None]
    h /= np.linalg.norm(h, axis=2, keepdims=True)
    nh = np.clip(np.einsum("fnk,nk->fn", h, srf.n), 0.0, 1.0)
    return srf.ks[None] * nh ** srf.shininess[None]


def _exposed(img: np.ndarray, model: ImagingModel, rng: np.random.Generator) -> np.ndarray:
    """The sensor on the irradiance ``img`` (f, H, W, C) float32, in place: lens blur, shot and read noise (from
    ``rng``), clipping and quantisation to ``model.bits``, back in [0, 1]."""
    f, H, W, C = img.shape
    if model.camera_blur > 0:
        for i in range(f):  # one OpenCV call per image, not per pixel
            img[i] = cv2.GaussianBlur(img[i], (0, 0), model.camera_blur,
                                      borderType=cv2.BORDER_REPLICATE).reshape(H, W, C)
    if model.full_well > 0:
        std = np.sqrt(np.maximum(img, 0) * np.float32(model.full_well) + np.float32(model.read_noise ** 2))
        img += std * rng.standard_normal(img.shape, dtype=np.float32) / np.float32(model.full_well)
    img *= np.float32(model.max_value)
    np.clip(img, 0, model.max_value, out=img)
    np.rint(img, out=img)
    img /= np.float32(model.max_value)
    return img


def _per_pixel(values: np.ndarray, idx: np.ndarray, size: tuple[int, int], fill, shape=()) -> np.ndarray:
    """(H, W, *shape) image of per-seen-pixel ``values`` (N, *shape) at flat indices ``idx``, ``fill`` elsewhere."""
    out = np.full((size[0] * size[1],) + shape, fill, dtype=values.dtype)
    out[idx] = values
    return out.reshape(size + shape)


def _per_light(per_light: np.ndarray, idx: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(f, H, W) bool images of the (f, N) per-seen-pixel ``per_light``, False where no pixel is seen."""
    out = np.zeros((len(per_light), size[0] * size[1]), dtype=bool)
    out[:, idx] = per_light
    return out.reshape((len(per_light),) + size)


def _occluded(vertices: np.ndarray, triangles: np.ndarray, T_world_cam: np.ndarray, x: np.ndarray,
              n: np.ndarray, l_dir: np.ndarray, dist: np.ndarray, todo: np.ndarray, eps: float) -> np.ndarray:
    """(f, N) bool: the shadow ray from ``x + eps * n`` along ``l_dir`` hits a triangle before ``dist``.

    Only the (light, pixel) pairs in ``todo`` are cast, all in one Open3D batch (scene built once).
    """
    scene = raycasting_scene(vertices, triangles)
    fi, ni = np.nonzero(todo)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    origins = (x[ni] + eps * n[ni]) @ R.T + t
    dirs = l_dir[fi, ni] @ R.T
    rays = np.concatenate([origins, dirs], axis=1).astype(np.float32)
    t_hit = query_scene(scene, "cast_rays", rays)["t_hit"]
    out = np.zeros(todo.shape, dtype=bool)
    out[fi, ni] = t_hit < dist[fi, ni] - eps
    return out
