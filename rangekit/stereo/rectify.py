"""Stereo rectification (Fusiello 12.5): rotate both cameras about their centres so that rows are epipolar
lines, and resample both images onto the rectified grids.

Frames: the rectified-left frame is the left camera frame rotated by ``R1`` (``X_rect = R1 @ X_left``),
origin at the left centre."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import invert_T, make_T

__all__ = ["Rectification", "rectify", "rectify_images", "rectify_pixels"]


@dataclass(frozen=True, eq=False, repr=False)
class Rectification:
    """A rectified stereo pair (``cv2.stereoRectify`` with ``CALIB_ZERO_DISPARITY``).

    R1, R2 : (3, 3) float64 rotations from the left / right camera frame to its rectified frame.
    P1, P2 : (3, 4) float64 projection matrices of the rectified cameras, both on points in the
        rectified-left frame: ``P1 = [K' | 0]``, ``P2 = [K' | (-focal * baseline, 0, 0)]``.
    Q : (4, 4) float64 disparity-to-depth matrix (``cv2.reprojectImageTo3D``).
    size : (width, height) of the rectified images in pixels (that of the input images).
    baseline : metres between the optical centres (> 0: the right camera is on the left's +x side).
    focal : rectified focal length in pixels (fx = fy of ``K'``).
    T_world_rect : (4, 4) float64 pose of the rectified-left frame, ``p_world = T_world_rect @ p_rect``.
    map_left, map_right : ((H, W) float32, (H, W) float32) ``cv2.remap`` tables: the raw pixel (x, y)
        each rectified pixel samples.
    """

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    size: tuple[int, int]
    baseline: float
    focal: float
    T_world_rect: np.ndarray
    map_left: tuple[np.ndarray, np.ndarray]
    map_right: tuple[np.ndarray, np.ndarray]

    @property
    def cx(self) -> float:
        return float(self.P1[0, 2])

    @property
    def cy(self) -> float:
        return float(self.P1[1, 2])

    def cameras(self) -> tuple[PinholeCamera, PinholeCamera]:
        """The two rectified (distortion-free, row-aligned) cameras in the world frame, left then right."""
        K = self.P1[:, :3].copy()
        w, h = self.size
        left = PinholeCamera(K, w, h, np.zeros(5), self.T_world_rect, "rectified_left")
        right = PinholeCamera(K, w, h, np.zeros(5), self.T_world_rect @ make_T(t=[self.baseline, 0.0, 0.0]),
                              "rectified_right")
        return left, right

    def __repr__(self) -> str:
        w, h = self.size
        return (f"Rectification({w}x{h}, focal={self.focal:.2f} px, baseline={self.baseline * 1e3:.2f} mm, "
                f"cx={self.cx:.2f}, cy={self.cy:.2f})")


def rectify(left: PinholeCamera, right: PinholeCamera, *, alpha: float = 0.0) -> Rectification:
    """Rectify a calibrated stereo pair (Fusiello 12.5; ``cv2.stereoRectify``, zero-disparity principal points).

    Parameters
    ----------
    left, right : the two cameras (same image size), posed in one world frame; the right camera must lie on
        the left camera's +x side (a horizontal pair).
    alpha : 0 keeps only valid pixels in the rectified images (zoomed in), 1 keeps every source pixel
        (black borders), as in OpenCV.

    Raises
    ------
    InputError
        If the sizes differ, the cameras coincide, the pair is vertical, or right is left of left.
    """
    if left.size != right.size:
        raise InputError(f"left camera {left.name!r} is {left.width}x{left.height} but right camera "
                         f"{right.name!r} is {right.width}x{right.height}; a stereo pair needs one image size")
    if not (0.0 <= alpha <= 1.0):
        raise InputError(f"rectify: alpha must be in [0, 1], found {alpha!r}")
    T_right_left = invert_T(right.T_world_cam) @ left.T_world_cam
    R, t = T_right_left[:3, :3], T_right_left[:3, 3]
    B = float(np.linalg.norm(t))
    if B < 1e-6:
        raise InputError(f"rectify: the cameras {left.name!r} and {right.name!r} share their optical centre "
                         f"(baseline {B:.3g} m); stereo needs a baseline")
    size = (left.width, left.height)
    d1 = left.dist if left.dist.size else np.zeros(5)
    d2 = right.dist if right.dist.size else np.zeros(5)
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(left.K, d1, right.K, d2, size, R, t.reshape(3, 1),
                                               flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha)
    if abs(P2[1, 3]) > abs(P2[0, 3]):
        raise InputError(f"rectify: the pair is vertical (right camera offset {np.round(-t, 4).tolist()} m in the "
                         "left frame); only horizontal pairs are supported")
    if P2[0, 3] > 0:
        raise InputError(f"rectify: camera {right.name!r} is on the -x side of {left.name!r} (offset "
                         f"{np.round(-R.T @ t, 4).tolist()} m in the left frame); swap left and right")
    focal = float(P1[0, 0])
    baseline = float(-P2[0, 3] / P2[0, 0])
    maps = []
    for cam, d, Rr, P in ((left, d1, R1, P1), (right, d2, R2, P2)):
        mx, my = cv2.initUndistortRectifyMap(cam.K, d, Rr, P, size, cv2.CV_32FC1)
        mx.flags.writeable = False
        my.flags.writeable = False
        maps.append((mx, my))
    T_world_rect = left.T_world_cam @ make_T(R1.T)
    return Rectification(R1=R1, R2=R2, P1=P1, P2=P2, Q=Q, size=size, baseline=baseline, focal=focal,
                         T_world_rect=T_world_rect, map_left=maps[0], map_right=maps[1])


def rectify_images(rect: Rectification, left_img: np.ndarray, right_img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Resample a raw image pair onto the rectified grids (bilinear, ``cv2.remap``); dtype kept.

    Raises
    ------
    InputError
        If an image does not have the rectification's size.
    """
    out = []
    for name, img, (mx, my) in (("left", left_img, rect.map_left), ("right", right_img, rect.map_right)):
        a = np.asarray(img)
        if a.shape[:2] != (rect.size[1], rect.size[0]):
            raise InputError(f"{name} image is {a.shape[1] if a.ndim > 1 else '?'}x{a.shape[0]} but the "
                             f"cameras are {rect.size[0]}x{rect.size[1]} (width x height)")
        if a.dtype == np.bool_ or a.dtype == np.float16:
            a = a.astype(np.float32)
        out.append(cv2.remap(a, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
    return out[0], out[1]


def rectify_pixels(rect: Rectification, camera: PinholeCamera, uv: np.ndarray, *, right: bool = False) -> np.ndarray:
    """(N, 2) float64 rectified pixels of raw (distorted) pixels ``uv`` (N, 2) of the rectification's left camera
    (``right=True``: its right camera), ``camera`` being that camera: the lens model's inverse
    (:meth:`PinholeCamera.pixels_to_normalized`), the rotation ``R1`` (``R2``), the rectified intrinsics. Points,
    not images: no resampling. NaN where the lens model cannot be inverted or the ray points behind the rectified
    image plane; a NaN pixel stays NaN.

    Raises
    ------
    InputError
        If ``camera`` does not have the rectification's size, or ``uv`` is not (N, 2).
    """
    if camera.size != tuple(rect.size):
        raise InputError(f"rectify_pixels: camera {camera.name!r} is {camera.width}x{camera.height} but the "
                         f"rectification is {rect.size[0]}x{rect.size[1]} (width x height)")
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise InputError(f"rectify_pixels: uv must be an (N, 2) array of (u, v) pixels, found shape {uv.shape}")
    finite = np.isfinite(uv).all(axis=1)
    xy = camera.pixels_to_normalized(np.where(finite[:, None], uv, 0.0))
    X = np.column_stack([xy, np.ones(len(xy))]) @ (rect.R2 if right else rect.R1).T
    P = rect.P2 if right else rect.P1
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.column_stack([P[0, 0] * X[:, 0] / X[:, 2] + P[0, 2], P[1, 1] * X[:, 1] / X[:, 2] + P[1, 2]])
    out[~finite | ~(X[:, 2] > 0)] = np.nan
    return out
