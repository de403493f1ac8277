"""Depth from one camera and a random-dot projector (Kinect v1, PrimeSense; Fusiello 13.2.2).

The projector is an inverse camera showing a fixed dot pattern; instead of the pattern itself the sensor keeps a
*reference image*: the camera's own image of the dots on a plane at a known distance ``Z0`` along its axis. Each
window of a new image is matched against the reference along the baseline, and the disparity ``m`` (pixels the
dots moved from where the plane showed them) gives the depth, inversely:

    f B / Z = m + f B / Z_ref(u - m, v)

in the camera rectified against the projector (``f`` its focal length in pixels, ``B`` the baseline, ``Z_ref`` the
reference plane's depth along the rectified ray; ``Z_ref = Z0`` when the projector is parallel to the camera). The
right-hand side is the camera-projector pair's ordinary stereo disparity, so the rest is
:mod:`rangekit.stereo`'s: the camera rectified against a virtual camera at the projector's pose (its intrinsics the
camera's: only its pose defines the epipolar geometry), both images resampled with the camera's map, census + SGM
with the capture as the left image and the reference as the right, subpixel, left-right check (the occlusion mask),
uniqueness (the confidence), then depth on the raw camera grid.

Frames: depth is z in the camera frame, points in the rig's world frame (metres).
"""

from __future__ import annotations

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.stereo.matching import DisparityMap, as_grey, sgm_disparity
from rangekit.stereo.pipeline import StereoResult, on_left_grid
from rangekit.stereo.rectify import Rectification, rectify

__all__ = ["dots_depth", "reference_disparity"]


def reference_disparity(rect: Rectification, reference_distance: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The stereo disparity ``f B / Z`` (pixels) of the reference plane (``z = reference_distance`` metres in the
    camera frame) at rectified pixels ``(u, v)`` (any shape): affine in them, as ``1 / Z`` is on a plane."""
    n = rect.R1[:, 2]                      # the camera's z axis in the rectified frame: the plane is n . X = Z0
    f = rect.focal
    return f * rect.baseline / float(reference_distance) * (n[0] * (u - rect.cx) / f + n[1] * (v - rect.cy) / f + n[2])


def dots_depth(image: np.ndarray, reference: np.ndarray, camera: PinholeCamera, projector: PinholeCamera,
               reference_distance: float, *, min_depth: float = 0.4, max_depth: float = 4.0,
               where: str = "reference image", **options) -> StereoResult:
    """Depth of ``camera`` from its ``image`` of the dots and its ``reference`` image of them on the plane at
    ``reference_distance`` metres (module doc).

    Parameters
    ----------
    image, reference : (H, W) or (H, W, 3) raw images of ``camera`` (its size).
    camera, projector : the calibrated camera and dot projector (the projector on the camera's +x side).
    reference_distance : metres along the camera's optical axis (> 0).
    min_depth, max_depth : metres; the disparities searched cover them.
    where : names the reference image in errors.
    **options : :func:`rangekit.stereo.matching.sgm_disparity`'s (``P1``, ``P2``, ``uniqueness``, ``prefilter``...).

    Returns
    -------
    StereoResult: ``depth`` (H, W) camera z on the raw grid (NaN where unmatched: no dot, occluded, ambiguous),
    ``confidence``, world ``points``, and its ``disparity`` the pair's stereo disparity ``f B / Z`` on the rectified
    grid.
    """
    size = (camera.height, camera.width)
    img, ref = as_grey(image, "image"), as_grey(reference, where)
    if img.shape != size:
        raise InputError(f"image is {img.shape[1]}x{img.shape[0]} but the camera {camera.name!r} is "
                         f"{camera.width}x{camera.height} (width x height)")
    if ref.shape != size:
        raise InputError(f"{where}: is {ref.shape[1]}x{ref.shape[0]}, expected the camera's {camera.width}x"
                         f"{camera.height} (width x height): the reference must be this camera's image of the plane")
    if not (np.isfinite(reference_distance) and reference_distance > 0):
        raise InputError(f"reference_distance must be > 0 metres, found {reference_distance!r}")
    if not (0 < min_depth < max_depth):
        raise InputError(f"need 0 < min_depth < max_depth (metres), found {min_depth!r}, {max_depth!r}")
    virtual = PinholeCamera(camera.K, camera.width, camera.height, np.zeros(5), projector.T_world_cam,
                            name=projector.name)
    rect = rectify(camera, virtual)
    mx, my = rect.map_left
    img_r = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    ref_r = cv2.remap(ref, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    H, W = size
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    d_ref = reference_disparity(rect, reference_distance, u, v)
    fB = rect.focal * rect.baseline
    lo = int(np.floor(fB / max_depth - d_ref.max()))
    hi = int(np.ceil(fB / min_depth - d_ref.min()))
    num = max(16, -(-(hi - lo) // 16) * 16)
    matched = sgm_disparity(img_r, ref_r, min_disparity=lo, num_disparities=min(num, 256), **options)
    m = matched.disparity.astype(np.float64)
    d = m + reference_disparity(rect, reference_distance, u - m, v)      # the pair's stereo disparity f B / Z
    disparity = DisparityMap(d.astype(np.float32), matched.confidence, matched.method, matched.min_disparity,
                             matched.num_disparities)
    return on_left_grid(disparity, rect, camera)
