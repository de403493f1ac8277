"""Active stereo: rectification, census + semi-global matching, disparity to depth (Fusiello ch. 12, 13.2.1).

The pipeline (:func:`stereo_depth`):

1. **Rectify** (:func:`rectify`, Fusiello 12.5): rotate both cameras about their centres so that their image
   planes coincide and rows are epipolar lines (``cv2.stereoRectify``, zero-disparity principal points),
   undistort and resample both images (:func:`rectify_images`). A point at depth z (rectified-left frame)
   then appears at the same row in both images, ``d = u_left - u_right = f B / z`` pixels apart.
2. **Match** (:func:`sgm_disparity`): census transform (bit string of "neighbour darker than centre" over a
   window, Zabih & Woodfill 1994), Hamming matching cost, semi-global aggregation along 4 or 8 paths
   (Hirschmuller 2008)::

       L_r(p, d) = C(p, d) + min(L_r(p - r, d), L_r(p - r, d +- 1) + P1, min_k L_r(p - r, k) + P2)
                   - min_k L_r(p - r, k)

   summed over the paths, winner-take-all, uniqueness test, left-right consistency check (Fusiello
   12.6.2: the right image's best match must point back), sub-pixel fit on the aggregated cost, optional
   3 x 3 median. :func:`sgbm_disparity` runs OpenCV's StereoSGBM instead, with the same output.
3. **Triangulate** (:func:`disparity_to_depth`, :func:`disparity_to_points`, :func:`depth_in_camera`):
   z = f B / d, and back to the original (distorted) left camera's pixel grid.

Frames: the rectified-left frame is the left camera frame rotated by ``R1`` (``X_rect = R1 @ X_left``),
origin at the left centre. Disparities are in rectified pixels, depths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rangekit.stereo import _kernels as _k
from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import apply_T, invert_T, make_T

__all__ = ["Rectification", "DisparityMap", "StereoResult", "rectify", "rectify_images", "census_transform",
           "census_cost", "sgm_disparity", "sgbm_disparity", "disparity_to_depth", "disparity_to_points",
           "depth_in_camera", "stereo_depth"]


# ------------------------------------------------------------------------------------------ results
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


@dataclass(frozen=True, eq=False, repr=False)
class DisparityMap:
    """Disparities of a rectified pair.

    disparity : (H, W) float32 ``u_left - u_right`` in rectified pixels at each rectified-left pixel; NaN
        where no reliable match (not unique, failed the left-right check, outside the search range).
    confidence : (H, W) float32 in [0, 1]; higher is better (census-SGM: ``1 - best / second best``
        aggregated cost, the second best at least 2 disparities away; SGBM: 1 where valid, 0 elsewhere).
    method : "census-sgm" or "sgbm".
    min_disparity, num_disparities : the search range ``[min_disparity, min_disparity + num_disparities)``.
    """

    disparity: np.ndarray
    confidence: np.ndarray
    method: str
    min_disparity: int
    num_disparities: int

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool, pixels with a disparity."""
        return np.isfinite(self.disparity)

    def __repr__(self) -> str:
        H, W = self.disparity.shape
        return (f"DisparityMap({self.method}, {W}x{H}, range=[{self.min_disparity}, "
                f"{self.min_disparity + self.num_disparities}), valid={self.valid.mean():.3f})")


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


# ------------------------------------------------------------------------------------------ input checks
def _grey(img: np.ndarray, name: str) -> np.ndarray:
    """(H, W) float32 from an (H, W) or (H, W, 3) RGB image of any real dtype."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 3:
        a = a.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim != 2:
        raise InputError(f"{name} image must be (H, W) grey or (H, W, 3) RGB, found shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)) or a.dtype == np.bool_:
        raise InputError(f"{name} image must be an integer or float array, found dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _pair(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    L, R = _grey(left, "left"), _grey(right, "right")
    if L.shape != R.shape:
        raise InputError(f"left image is {L.shape[1]}x{L.shape[0]} but right is {R.shape[1]}x{R.shape[0]} "
                         "(width x height); a stereo pair needs two images of one size")
    if min(L.shape) < 8:
        raise InputError(f"stereo images must be at least 8x8 pixels, found {L.shape[1]}x{L.shape[0]}")
    if not (np.all(np.isfinite(L)) and np.all(np.isfinite(R))):
        raise InputError("stereo images must be finite; found NaN or inf (fill invalid pixels first)")
    return L, R


def _search_range(min_disparity: int, num_disparities: int, width: int) -> tuple[int, int]:
    if int(min_disparity) != min_disparity or int(num_disparities) != num_disparities:
        raise InputError(f"min_disparity and num_disparities must be integers, found {min_disparity!r}, "
                         f"{num_disparities!r}")
    if num_disparities < 16 or num_disparities % 16:
        raise InputError(f"num_disparities must be a positive multiple of 16 (as OpenCV), found {num_disparities}")
    if num_disparities > 256:
        raise InputError(f"num_disparities must be <= 256, found {num_disparities}")
    if min_disparity + num_disparities > width:
        raise InputError(f"disparity range [{min_disparity}, {min_disparity + num_disparities}) does not fit in "
                         f"an image {width} pixels wide")
    return int(min_disparity), int(num_disparities)


# ------------------------------------------------------------------------------------------ rectification
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


# ------------------------------------------------------------------------------------------ matching
def census_transform(img: np.ndarray, window: tuple[int, int] = (7, 5)) -> np.ndarray:
    """Census transform: per pixel, one bit per window neighbour, 1 where the neighbour is darker than the centre.

    Parameters
    ----------
    img : (H, W) or (H, W, 3) image, any real dtype.
    window : (width, height), odd, with width * height - 1 <= 64 bits; default 7 x 5 (34 bits).

    Returns
    -------
    (H, W) uint64 bit strings (row-major window order, centre skipped, border replicated).
    """
    a = _grey(img, "census")
    w, h = (int(window[0]), int(window[1])) if np.ndim(window) == 1 and len(window) == 2 else (0, 0)
    if w < 3 or h < 1 or w % 2 == 0 or h % 2 == 0 or w * h - 1 > 64:
        raise InputError(f"census window must be (width, height), both odd, width >= 3, width * height <= 65, "
                         f"found {window!r}")
    out = np.empty(a.shape, np.uint64)
    _k.census(a, w // 2, h // 2, out)
    return out


def census_cost(left_rect: np.ndarray, right_rect: np.ndarray, *, min_disparity: int = 0,
                num_disparities: int = 64, window: tuple[int, int] = (9, 7)) -> np.ndarray:
    """(H, W, D) uint8 Hamming distance between the left census at (x, y) and the right one at (x - d, y),
    ``d = min_disparity + k``; ``window[0] * window[1] - 1`` (the largest cost) where x - d is outside."""
    L, R = _pair(left_rect, right_rect)
    min_d, D = _search_range(min_disparity, num_disparities, L.shape[1])
    cl, cr = census_transform(L, window), census_transform(R, window)
    cost = np.empty(L.shape + (D,), np.uint8)
    _k.hamming_cost(cl, cr, min_d, np.uint8(window[0] * window[1] - 1), cost)
    return cost


_SUBPIXEL = {"none": 0, "parabola": 1, "equiangular": 2}


def sgm_disparity(left_rect: np.ndarray, right_rect: np.ndarray, *, min_disparity: int = 0,
                  num_disparities: int = 64, window: tuple[int, int] = (9, 7), P1: int = 10, P2: int = 120,
                  paths: int = 8, uniqueness: float = 0.05, lr_max_diff: int = 1, prefilter: float = 1.0,
                  subpixel: str = "equiangular", median: bool = True) -> DisparityMap:
    """Census + semi-global matching of a rectified pair (Hirschmuller 2008), the left image as reference.

    Parameters
    ----------
    left_rect, right_rect : (H, W) rectified images (any real dtype; RGB is converted to grey).
    min_disparity, num_disparities : search ``d`` in ``[min_disparity, min_disparity + num_disparities)``
        pixels; ``num_disparities`` a multiple of 16, at most 256.
    window : census window (width, height), odd; the cost is a Hamming distance in [0, w * h - 1].
        Default 9 x 7 (62 bits, still one uint64).
    P1, P2 : SGM penalties (cost units) for a disparity change of 1 and of more than 1 between neighbours
        along a path; ``P1 < P2``.
    paths : 4 (horizontal + vertical) or 8 (also the diagonals).
    uniqueness : the best aggregated cost must be <= (1 - uniqueness) x the best one at least 2 disparities
        away (OpenCV's uniquenessRatio / 100).
    lr_max_diff : largest |d_left - d_right| in pixels kept by the left-right check; < 0 disables the check.
    subpixel : "equiangular" (V fit, suits census/absolute costs), "parabola" or "none".
    prefilter : Gaussian sigma in pixels applied to both images before the census (0: none). Census bits
        compare single pixels, so in the dark gaps between projected dots they follow the sensor noise;
        a sigma of 1 px raises the matched fraction and the sub-pixel precision (docs/stereo.md).
    median : 3 x 3 median over the valid neighbours after the checks.

    Returns
    -------
    DisparityMap with ``method="census-sgm"``.

    Raises
    ------
    InputError
        On images of different sizes, a bad search range, ``P1 >= P2``, ``paths`` not 4 or 8, or an unknown
        ``subpixel``.
    """
    if paths not in (4, 8):
        raise InputError(f"sgm_disparity: paths must be 4 or 8, found {paths!r}")
    if not (0 <= P1 < P2 <= 4000):
        raise InputError(f"sgm_disparity: need 0 <= P1 < P2 <= 4000 (cost units), found P1={P1}, P2={P2}")
    if subpixel not in _SUBPIXEL:
        raise InputError(f"sgm_disparity: subpixel must be one of {sorted(_SUBPIXEL)}, found {subpixel!r}")
    if not (0.0 <= uniqueness < 1.0):
        raise InputError(f"sgm_disparity: uniqueness must be in [0, 1), found {uniqueness!r}")
    if not (0.0 <= prefilter <= 10.0):
        raise InputError(f"sgm_disparity: prefilter must be a Gaussian sigma in [0, 10] pixels, found {prefilter!r}")
    left_rect, right_rect = _pair(left_rect, right_rect)
    if prefilter > 0:
        left_rect = cv2.GaussianBlur(left_rect, (0, 0), prefilter, borderType=cv2.BORDER_REPLICATE)
        right_rect = cv2.GaussianBlur(right_rect, (0, 0), prefilter, borderType=cv2.BORDER_REPLICATE)
    # Matching cost: Hamming distance of census bit strings.
    cost = census_cost(left_rect, right_rect, min_disparity=min_disparity, num_disparities=num_disparities,
                       window=window)
    H, W, D = cost.shape
    min_d = int(min_disparity)
    # Semi-global aggregation: S(p, d) = sum_r L_r(p, d).
    acc_f = np.empty((H, W, D), np.uint16)
    acc_r = np.empty((H, W, D), np.uint16)
    _k.aggregate(cost, np.int32(P1), np.int32(P2), paths == 8, acc_f, acc_r)
    del cost
    # Winner-take-all, uniqueness, sub-pixel fit.
    disp = np.empty((H, W), np.float32)
    dint = np.empty((H, W), np.int32)
    conf = np.empty((H, W), np.float32)
    _k.winner_take_all(acc_f, acc_r, min_d, float(uniqueness), _SUBPIXEL[subpixel], disp, dint, conf)
    # Left-right consistency (occlusions and mismatches).
    if lr_max_diff >= 0:
        dright = np.empty((H, W), np.int32)
        _k.right_winner(acc_f, acc_r, min_d, dright)
        _k.lr_check(dint, dright, int(lr_max_diff), disp)
    if median:
        out = np.empty_like(disp)
        _k.median3(disp, out)
        disp = out
    conf = np.where(np.isfinite(disp), np.clip(conf, 0.0, 1.0), 0.0).astype(np.float32)
    return DisparityMap(disparity=disp, confidence=conf, method="census-sgm", min_disparity=min_d,
                        num_disparities=D)


def sgbm_disparity(left_rect: np.ndarray, right_rect: np.ndarray, *, min_disparity: int = 0,
                   num_disparities: int = 64, block_size: int = 5, P1: int | None = None, P2: int | None = None,
                   uniqueness: float = 0.05, lr_max_diff: int = 1, speckle_window: int = 0,
                   speckle_range: int = 2, mode: str = "sgbm") -> DisparityMap:
    """OpenCV's StereoSGBM on a rectified pair, with the output of :func:`sgm_disparity`.

    Images are converted to uint8 (float images in [0, 1] are scaled by 255, uint16 shifted to 8 bits).
    ``P1``, ``P2`` default to OpenCV's recommended ``8 * block_size**2`` and ``32 * block_size**2``;
    ``lr_max_diff`` is ``disp12MaxDiff``, ``uniqueness`` is ``uniquenessRatio / 100``; ``mode`` is "sgbm"
    (5 paths), "hh" (8 paths, full-width) or "3way". OpenCV's disparities (int16, 1/16 pixel) are divided by
    16; invalid ones become NaN. ``confidence`` is 1 where valid, 0 elsewhere (OpenCV gives none).
    """
    L, R = _pair(left_rect, right_rect)
    min_d, D = _search_range(min_disparity, num_disparities, L.shape[1])
    modes = {"sgbm": cv2.STEREO_SGBM_MODE_SGBM, "hh": cv2.STEREO_SGBM_MODE_HH,
             "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY}
    if mode not in modes:
        raise InputError(f"sgbm_disparity: mode must be one of {sorted(modes)}, found {mode!r}")
    if block_size < 1 or block_size % 2 == 0:
        raise InputError(f"sgbm_disparity: block_size must be odd and >= 1, found {block_size}")

    def u8(a: np.ndarray, src: np.ndarray) -> np.ndarray:
        src = np.asarray(src)
        if src.dtype == np.uint16:
            scale = 1.0 / 256.0
        elif np.issubdtype(src.dtype, np.floating) and float(np.max(a)) <= 1.0:
            scale = 255.0
        else:
            scale = 1.0
        return np.clip(np.rint(a * scale), 0, 255).astype(np.uint8)

    bs2 = block_size * block_size
    sgbm = cv2.StereoSGBM_create(minDisparity=min_d, numDisparities=D, blockSize=block_size,
                                 P1=8 * bs2 if P1 is None else int(P1), P2=32 * bs2 if P2 is None else int(P2),
                                 disp12MaxDiff=int(lr_max_diff), uniquenessRatio=int(round(100 * uniqueness)),
                                 speckleWindowSize=int(speckle_window), speckleRange=int(speckle_range),
                                 mode=modes[mode])
    raw = sgbm.compute(u8(L, left_rect), u8(R, right_rect))
    disp = raw.astype(np.float32) / 16.0
    disp[raw < min_d * 16] = np.nan
    return DisparityMap(disparity=disp, confidence=np.isfinite(disp).astype(np.float32), method="sgbm",
                        min_disparity=min_d, num_disparities=D)


# ------------------------------------------------------------------------------------------ triangulation
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


def _raw_to_rectified(rect: Rectification, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) rectified-left coordinates (u, v) of every raw left pixel centre."""
    xy = camera.pixels_to_normalized(camera.pixel_grid())          # the lens model's exact inverse
    X = np.column_stack([xy, np.ones(len(xy))]) @ rect.R1.T          # rays in the rectified-left frame
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


def _left_points(disparity, rect: Rectification, left_camera: PinholeCamera) -> np.ndarray:
    """(H, W, 3) left-camera-frame points on the raw left grid (see :func:`depth_in_camera`); NaN where invalid."""
    if left_camera.size != rect.size:
        raise InputError(f"left camera {left_camera.name!r} is {left_camera.width}x{left_camera.height} but the "
                         f"rectification is {rect.size[0]}x{rect.size[1]}")
    d_rect = _disparity_array(disparity, rect)
    u, v = _raw_to_rectified(rect, left_camera)
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
    return _left_points(disparity, rect, left_camera)[..., 2]


# ------------------------------------------------------------------------------------------ one call
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
    Lr, Rr = rectify_images(rect, _grey(L, "left"), _grey(R, "right"))
    dmap = methods[method](Lr, Rr, num_disparities=num_disparities, **options)
    X_left = _left_points(dmap, rect, left_cam)
    depth = X_left[..., 2]
    ok = np.isfinite(depth)
    u, v = _raw_to_rectified(rect, left_cam)
    ui = np.clip(np.rint(u), 0, rect.size[0] - 1).astype(np.int64)
    vi = np.clip(np.rint(v), 0, rect.size[1] - 1).astype(np.int64)
    conf = np.where(ok, dmap.confidence[vi, ui], 0.0).astype(np.float32)
    points = apply_T(left_cam.T_world_cam, X_left[ok])
    return StereoResult(depth=depth, confidence=conf, points=points, disparity=dmap, rectification=rect)
