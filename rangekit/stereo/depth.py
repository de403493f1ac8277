"""Disparity to depth and points (z = f B / d), in the rectified frame and back on the raw left camera's
pixel grid."""

from __future__ import annotations

import numpy as np

from rangekit.camera import PinholeCamera, pixel_rays
from rangekit.errors import InputError
from rangekit.geometry import apply_T
from rangekit.stereo.matching import DisparityMap
from rangekit.stereo.rectify import Rectification

__all__ = ["disparity_to_depth", "disparity_to_points", "depth_in_camera", "disparity_points"]


def _disparity_array(disparity, rect: Rectification) -> np.ndarray:
    d = disparity.disparity if isinstance(disparity, DisparityMap) else np.asarray(disparity)
    if d.shape != (rect.size[1], rect.size[0]):
        raise InputError(f"disparity map is {d.shape[1] if d.ndim > 1 else '?'}x{d.shape[0]} but the rectified "
                         f"images are {rect.size[0]}x{rect.size[1]} (width x height)")
    return d.astype(np.float64)


def disparity_to_depth(disparity: np.ndarray | DisparityMap, rect: Rectification) -> np.ndarray:
    """(H, W) float64 depth z = focal * baseline / d in the rectified-left frame, metres; NaN where d <= 0 or NaN."""
    d = _disparity_array(disparity, rect)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = rect.focal * rect.baseline / d
    z[~(d > 0)] = np.nan
    return z


def _rect_points(z: np.ndarray, u: np.ndarray, v: np.ndarray, rect: Rectification) -> np.ndarray:
    """(..., 3) points in the rectified-left frame from depth z at rectified pixels (u, v)."""
    f = rect.focal
    return np.stack([(u - rect.cx) * z / f, (v - rect.cy) * z / f, z], axis=-1)


def disparity_to_points(disparity: np.ndarray | DisparityMap, rect: Rectification,
                        T_world_left: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) float64 points, metres, one per valid disparity pixel (row-major).

    In the world frame given by ``T_world_left`` (the left camera's pose, ``p_world = T_world_left @ p_left``);
    in the left camera frame when it is None.
    """
    z = disparity_to_depth(disparity, rect)
    ok = np.isfinite(z)
    v, u = np.nonzero(ok)
    X_rect = _rect_points(z[ok], u.astype(np.float64), v.astype(np.float64), rect)
    X_left = X_rect @ rect.R1  # R1^T @ X for each row
    return X_left if T_world_left is None else apply_T(np.asarray(T_world_left, np.float64), X_left)


def disparity_points(u, v, disparity, rect: Rectification) -> np.ndarray:
    """(N, 3) float64 world points, metres, of scattered rectified-left pixels ``(u, v)`` (N,) at ``disparity``
    (N,) rectified pixels: z = focal * baseline / d in the rectified-left frame, carried into the world by
    ``rect.T_world_rect``. NaN rows where d <= 0 or any input is NaN."""
    u, v, d = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (u, v, disparity))
    if not (u.shape == v.shape == d.shape):
        raise InputError(f"disparity_points: u, v and disparity must have one length, found {u.size}, {v.size}, "
                         f"{d.size}")
    with np.errstate(divide="ignore", invalid="ignore"):
        z = rect.focal * rect.baseline / d
    z[~(d > 0)] = np.nan
    return apply_T(rect.T_world_rect, _rect_points(z, u, v, rect))


def raw_to_rectified(rect: Rectification, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) rectified-left coordinates (u, v) of every raw left pixel centre."""
    X = pixel_rays(camera).reshape(-1, 3) @ rect.R1.T               # rays in the rectified-left frame
    P = rect.P1
    u = (P[0, 0] * X[:, 0] + P[0, 2] * X[:, 2]) / X[:, 2]
    v = (P[1, 1] * X[:, 1] + P[1, 2] * X[:, 2]) / X[:, 2]
    return u.reshape(camera.height, camera.width), v.reshape(camera.height, camera.width)


def _bilinear_all_valid(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``img`` at (u, v); NaN unless all 4 neighbours are inside and finite."""
    H, W = img.shape
    u0, v0 = np.floor(u), np.floor(v)
    inside = (u0 >= 0) & (v0 >= 0) & (u0 <= W - 2) & (v0 <= H - 2)
    i0 = np.where(inside, u0, 0).astype(np.int64)
    j0 = np.where(inside, v0, 0).astype(np.int64)
    fu, fv = u - i0, v - j0
    a, b = img[j0, i0], img[j0, i0 + 1]
    c, d = img[j0 + 1, i0], img[j0 + 1, i0 + 1]
    out = (a * (1 - fu) + b * fu) * (1 - fv) + (c * (1 - fu) + d * fu) * fv
    out[~inside] = np.nan  # NaN neighbours already propagate
    return out


def left_points(disparity, rect: Rectification, left_camera: PinholeCamera) -> np.ndarray:
    """(H, W, 3) left-camera-frame points on the raw left grid (see :func:`depth_in_camera`); NaN where invalid."""
    if left_camera.size != rect.size:
        raise InputError(f"left camera {left_camera.name!r} is {left_camera.width}x{left_camera.height} but the "
                         f"rectification is {rect.size[0]}x{rect.size[1]}")
    d_rect = _disparity_array(disparity, rect)
    u, v = raw_to_rectified(rect, left_camera)
    d = _bilinear_all_valid(d_rect, u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = rect.focal * rect.baseline / d
    z[~(d > 0)] = np.nan
    return _rect_points(z, u, v, rect) @ rect.R1  # R1^T @ X_rect per pixel


def depth_in_camera(disparity: np.ndarray | DisparityMap, rect: Rectification,
                    left_camera: PinholeCamera) -> np.ndarray:
    """(H, W) float64 depth (z in the original left camera frame, metres) on the raw left pixel grid.

    Every raw left pixel is mapped to rectified coordinates (the lens model's inverse, then ``R1``, ``P1``), the
    disparity is sampled bilinearly there (NaN unless all 4 neighbours are valid), triangulated in the
    rectified frame and rotated back by ``R1^T``. Compares directly with a left camera's true depth map.
    Bilinear interpolation of disparity is exact on planes (1/z is affine in rectified pixels there).
    """
    return left_points(disparity, rect, left_camera)[..., 2]
