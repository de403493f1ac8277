"""Laser peaks to 3D points: each peak's camera ray against the laser's plane (Fusiello 13.2.4, eq. 13.7).

A lit pixel (u, v) (subpixel, as detected in the DISTORTED image) is undone through the camera's lens
model (``PinholeCamera.rays``: Newton inversion of OpenCV's distortion, exact to ~1e-11 px), giving a
world ray ``C + t d``; the point is where it meets the light sheet ``n . X + d = 0``
(:func:`rangekit.geometry.ray_plane_t`, shared with coded light).

Refusals:

- a ray that meets the plane at a grazing angle (below ``min_angle``, default :data:`MIN_RAY_PLANE_ANGLE`
  = 2 degrees) gives NaN: the depth error grows as 1 / sin(angle) (a 0.05 px peak error at 2 degrees is
  already ~30x the error at a right angle) and at 0 the point is at infinity. Points behind the camera
  (t <= 0) give NaN too. Both are counted in the result;
- a plane that passes within :data:`MIN_CENTRE_DISTANCE` (1 mm) of the camera centre is refused with a
  :class:`~rangekit.errors.ConfigError` naming the laser: every ray of the camera then lies (nearly) in
  the plane or meets it only at the centre, so no pixel can be triangulated.

Profiles taken at turntable angle theta are brought into the frame of angle 0 by
:func:`to_turntable_frame` (``rangekit.rig.rig_file.table_motion(T_world_table, -theta)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import ConfigError, InputError
from rangekit.geometry import apply_T, ray_plane_t
from rangekit.rig.lasers import LineLaser
from rangekit.rig.rig_file import table_motion

__all__ = ["MIN_RAY_PLANE_ANGLE", "MIN_CENTRE_DISTANCE", "LaserPoints", "as_plane", "check_plane_camera",
           "triangulate_peaks", "to_turntable_frame", "plane_region"]

#: Smallest angle (radians) between a camera ray and the laser plane that is triangulated (2 degrees).
MIN_RAY_PLANE_ANGLE = math.radians(2.0)
#: A laser plane closer than this (metres) to the camera centre is refused: every ray is parallel to it.
MIN_CENTRE_DISTANCE = 1e-3


@dataclass(frozen=True, eq=False)
class LaserPoints:
    """Triangulated peaks of one laser frame.

    xyz : (N, 3) float64 world points, metres, row i from peak i; NaN where refused.
    angle : (N,) float64 angle between each ray and the plane, radians (NaN where the lens model could not
        be inverted); the depth error scales as 1 / sin(angle).
    n_grazing : peaks refused because their ray meets the plane below ``min_angle``.
    n_behind : peaks whose ray meets the plane behind the camera (t <= 0).
    n_invalid : peaks that were NaN on input or whose pixel the lens model could not invert.
    """

    xyz: np.ndarray
    angle: np.ndarray
    n_grazing: int
    n_behind: int
    n_invalid: int

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: the rows of ``xyz`` that hold a point."""
        return np.isfinite(self.xyz[:, 0])

    @property
    def points(self) -> np.ndarray:
        """(M, 3) the valid points only."""
        return self.xyz[self.valid]

    def __repr__(self) -> str:
        return (f"LaserPoints({int(self.valid.sum())} of {len(self.xyz)} peaks; refused: {self.n_grazing} "
                f"grazing, {self.n_behind} behind the camera, {self.n_invalid} invalid)")


def as_plane(laser_or_plane, name: str | None = None) -> tuple[np.ndarray, str]:
    """(4,) unit-normal plane ``[n, d]`` and a name for messages, from a LineLaser or a (4,) plane."""
    if isinstance(laser_or_plane, LineLaser):
        return laser_or_plane.plane, name or f"laser {laser_or_plane.name!r}"
    p = np.asarray(laser_or_plane, dtype=np.float64)
    label = name or "laser plane"
    if p.shape != (4,) or not np.all(np.isfinite(p)) or not np.linalg.norm(p[:3]) > 1e-12:
        raise InputError(f"{label}: must be a LineLaser or 4 finite numbers [nx, ny, nz, d] with a non-zero "
                         f"normal, found {p.tolist() if p.size <= 8 else p.shape}")
    return p / np.linalg.norm(p[:3]), label


def check_plane_camera(plane: np.ndarray, camera: PinholeCamera, label: str,
                       min_distance: float = MIN_CENTRE_DISTANCE) -> float:
    """Signed distance (metres) of ``camera``'s centre from the unit-normal ``plane``; ConfigError naming
    ``label`` when it is below ``min_distance`` (module doc)."""
    dist = float(plane[:3] @ camera.center + plane[3])
    if not abs(dist) >= min_distance:
        raise ConfigError(f"{label}: the plane {np.round(plane, 6).tolist()} passes within "
                          f"{abs(dist) * 1e3:.3f} mm of camera {camera.name!r}'s centre (at least "
                          f"{min_distance * 1e3:g} mm needed): every ray is parallel to it, nothing can be "
                          "triangulated; check the laser's plane in the rig file")
    return dist


def triangulate_peaks(points_uv, camera: PinholeCamera, laser, *,
                      min_angle: float = MIN_RAY_PLANE_ANGLE) -> LaserPoints:
    """Triangulate laser peaks against the laser plane, with the camera's lens distortion.

    Parameters
    ----------
    points_uv : (N, 2) subpixel peak positions ``(u, v)`` = (column, row) in the camera's (distorted) image,
        pixel centres at integers; NaN rows are passed through as NaN.
    camera : the calibrated camera (K, dist, ``T_world_cam``).
    laser : a :class:`~rangekit.rig.lasers.LineLaser` or its (4,) plane ``[n, d]`` in the world frame.
    min_angle : radians; rays meeting the plane at less than this are refused (NaN, counted).

    Returns
    -------
    :class:`LaserPoints` with (N, 3) world points, metres.

    Raises
    ------
    ConfigError : the plane passes within 1 mm of the camera centre (named in the message).
    InputError : ``points_uv`` is not (N, 2).
    """
    plane, label = as_plane(laser)
    uv = np.asarray(points_uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise InputError(f"triangulate_peaks: points_uv must be an (N, 2) array of (u, v) pixels, found shape "
                         f"{uv.shape}")
    if not (0.0 <= min_angle < math.pi / 2):
        raise InputError(f"triangulate_peaks: min_angle must be in [0, pi/2) radians, found {min_angle!r}")
    check_plane_camera(plane, camera, label)
    finite = np.all(np.isfinite(uv), axis=1)
    o, d = camera.rays(np.where(finite[:, None], uv, 0.0))
    d[~finite] = np.nan
    with np.errstate(invalid="ignore"):
        angle = np.arcsin(np.minimum(np.abs(d @ plane[:3]), 1.0))
    t = ray_plane_t(o, d, plane)
    invalid = ~np.isfinite(angle)
    grazing = ~invalid & (angle < min_angle)
    with np.errstate(invalid="ignore"):
        behind = ~invalid & ~grazing & ~(t > 0)
    keep = ~(invalid | grazing | behind)
    xyz = np.full((len(uv), 3), np.nan)
    xyz[keep] = o[keep] + t[keep, None] * d[keep]
    return LaserPoints(xyz=xyz, angle=angle, n_grazing=int(grazing.sum()), n_behind=int(behind.sum()),
                       n_invalid=int(invalid.sum()))


def to_turntable_frame(points, angle, T_world_table) -> np.ndarray:
    """Bring points seen with the turntable at ``angle`` into the frame of angle 0 (world coordinates of the
    object as it stood at angle 0).

    Parameters
    ----------
    points : (N, 3) world points, metres (NaN rows stay NaN).
    angle : the table angle in radians, one number for the whole profile, or (N,) one per point (several
        profiles at once).
    T_world_table : (4, 4) turntable frame (rotation axis = its z axis), as in the rig file.

    Returns
    -------
    (N, 3) float64: ``table_motion(T_world_table, -angle) @ X`` (:func:`rangekit.rig.rig_file.table_motion`).
    """
    P = np.asarray(points, dtype=np.float64)
    a = np.asarray(angle, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"to_turntable_frame: points must be (N, 3), found shape {P.shape}")
    if a.ndim == 0:
        return apply_T(table_motion(np.asarray(T_world_table, dtype=np.float64), -float(a)), P)
    if a.shape != (len(P),):
        raise InputError(f"to_turntable_frame: angle must be one number or one per point ({len(P)},), found "
                         f"shape {a.shape}")
    T = np.asarray(T_world_table, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    local = (P - t) @ R                  # table frame
    c, s = np.cos(-a), np.sin(-a)
    x = c * local[:, 0] - s * local[:, 1]
    y = s * local[:, 0] + c * local[:, 1]
    return np.column_stack([x, y, local[:, 2]]) @ R.T + t


def plane_region(camera: PinholeCamera, laser, T_world_table, *, z_min: float) -> np.ndarray:
    """(H, W) bool: the pixels whose ray meets the laser's plane in front of the camera at a point more than
    ``z_min`` metres above the turntable top (table frame z). A lit pixel outside it can only be the line on
    the table (or below it), so a peak finder can ignore it (:func:`rangekit.laser.detect_peaks`'s mask).

    Parameters
    ----------
    camera : the calibrated camera (its lens distortion included).
    laser : a :class:`~rangekit.rig.lasers.LineLaser` or a (4,) plane, world frame.
    T_world_table : (4, 4) the turntable frame (its z axis up, z = 0 its top).
    z_min : metres above the table top.
    """
    from rangekit.camera import world_pixel_rays
    from rangekit.geometry import invert_T

    plane, _ = as_plane(laser)
    o, d = world_pixel_rays(camera)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = ray_plane_t(o, d, plane)
        X = o + t[:, None] * d
        z = apply_T(invert_T(np.asarray(T_world_table, dtype=np.float64)), np.where(np.isfinite(X), X, 0.0))[:, 2]
        inside = np.isfinite(t) & (t > 0) & (z > z_min)
    return inside.reshape(camera.height, camera.width)
