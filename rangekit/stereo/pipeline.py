"""Depth of the left camera from a raw stereo pair in one call: rectify, match, triangulate."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import apply_T
from rangekit.stereo.depth import left_points, raw_to_rectified
from rangekit.stereo.matching import DisparityMap, as_grey, sgbm_disparity, sgm_disparity
from rangekit.stereo.rectify import Rectification, rectify, rectify_images

__all__ = ["StereoResult", "on_left_grid", "stereo_depth"]


@dataclass(frozen=True, eq=False, repr=False)
class StereoResult:
    """Output of :func:`stereo_depth`.

    depth : (H, W) float64 z in the original left camera frame, metres, on its raw (distorted) pixel grid;
        NaN where invalid. Compare directly with the left camera's ground-truth depth.
    confidence : (H, W) float32 in [0, 1] on the same grid (nearest rectified pixel); 0 where invalid.
    points : (N, 3) float64 world points, metres, one per valid ``depth`` pixel, row-major.
    disparity : the :class:`DisparityMap` on the rectified grid.
    rectification : the :class:`Rectification` used.
    """

    depth: np.ndarray
    confidence: np.ndarray
    points: np.ndarray
    disparity: DisparityMap
    rectification: Rectification

    def __repr__(self) -> str:
        ok = np.isfinite(self.depth)
        H, W = self.depth.shape
        rng = f"[{np.nanmin(self.depth):.3f}, {np.nanmax(self.depth):.3f}]" if ok.any() else "[]"
        return (f"StereoResult({self.disparity.method}, {W}x{H}, valid={ok.mean():.3f}, depth_m={rng}, "
                f"points={len(self.points)})")


def stereo_depth(left_img: np.ndarray, right_img: np.ndarray, left_cam: PinholeCamera, right_cam: PinholeCamera,
                 *, method: str = "census-sgm", min_depth: float = 0.4, num_disparities: int | None = None,
                 alpha: float = 0.0, **options) -> StereoResult:
    """Depth of the left camera from a raw (unrectified, distorted) stereo pair: rectify, match, triangulate.

    Parameters
    ----------
    left_img, right_img : (H, W) or (H, W, 3) raw images of ``left_cam`` and ``right_cam``.
    left_cam, right_cam : the calibrated cameras (e.g. ``load_rig(path).cameras``).
    method : "census-sgm" (:func:`sgm_disparity`) or "sgbm" (:func:`sgbm_disparity`).
    min_depth : metres; the nearest depth to search when ``num_disparities`` is None, which is then
        ``focal * baseline / min_depth`` rounded up to a multiple of 16 (min_disparity 0).
    num_disparities : explicit search range (multiple of 16).
    alpha : rectification free scaling (see :func:`rectify`).
    **options : passed to the matcher (``P1``, ``P2``, ``uniqueness``, ``paths``, ...).

    Returns
    -------
    StereoResult (depth and confidence on the raw left grid, world points, the disparity map, the rectification).

    Raises
    ------
    InputError
        If the images differ in size or do not match the cameras, or on a bad option.
    """
    methods = {"census-sgm": sgm_disparity, "sgbm": sgbm_disparity}
    if method not in methods:
        raise InputError(f"stereo_depth: method must be one of {sorted(methods)}, found {method!r}")
    L, R = np.asarray(left_img), np.asarray(right_img)
    if L.shape[:2] != R.shape[:2]:
        raise InputError(f"left image is {L.shape[1] if L.ndim > 1 else '?'}x{L.shape[0]} but right is "
                         f"{R.shape[1] if R.ndim > 1 else '?'}x{R.shape[0]} (width x height); a stereo pair "
                         "needs two images of one size")
    for name, img, cam in (("left", L, left_cam), ("right", R, right_cam)):
        if img.ndim < 2 or img.shape[:2] != (cam.height, cam.width):
            raise InputError(f"{name} image is {img.shape[1] if img.ndim > 1 else '?'}x{img.shape[0]} but "
                             f"camera {cam.name!r} is {cam.width}x{cam.height} (width x height); use the images "
                             "this rig recorded, or a rig calibrated at this resolution")
    rect = rectify(left_cam, right_cam, alpha=alpha)
    if num_disparities is None:
        if not (min_depth > 0):
            raise InputError(f"stereo_depth: min_depth must be > 0 metres, found {min_depth!r}")
        num_disparities = int(16 * np.ceil(rect.focal * rect.baseline / min_depth / 16))
        num_disparities = min(num_disparities, 256, 16 * (rect.size[0] // 16))
    Lr, Rr = rectify_images(rect, as_grey(L, "left"), as_grey(R, "right"))
    dmap = methods[method](Lr, Rr, num_disparities=num_disparities, **options)
    return on_left_grid(dmap, rect, left_cam)


def on_left_grid(dmap: DisparityMap, rect: Rectification, left_cam: PinholeCamera) -> StereoResult:
    """The :class:`StereoResult` of the disparity map ``dmap`` (``f B / Z`` on the rectified grid of ``rect``): depth
    and confidence (nearest rectified pixel) on the raw left grid, world points."""
    X_left = left_points(dmap, rect, left_cam)
    depth = X_left[..., 2]
    ok = np.isfinite(depth)
    u, v = raw_to_rectified(rect, left_cam)
    ui = np.clip(np.rint(u), 0, rect.size[0] - 1).astype(np.int64)
    vi = np.clip(np.rint(v), 0, rect.size[1] - 1).astype(np.int64)
    conf = np.where(ok, dmap.confidence[vi, ui], 0.0).astype(np.float32)
    points = apply_T(left_cam.T_world_cam, X_left[ok])
    return StereoResult(depth=depth, confidence=conf, points=points, disparity=dmap, rectification=rect)
