"""Stereo matching on a rectified pair: census transform, Hamming cost, semi-global aggregation
(Hirschmuller 2008) in compiled kernels, or OpenCV's StereoSGBM; both return a :class:`DisparityMap`."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rangekit.errors import InputError
from rangekit.image import to_grey
from rangekit.stereo import _kernels as _k
from rangekit.stereo import _sgm

__all__ = ["DisparityMap", "census_transform", "census_cost", "sgm_disparity", "sgbm_disparity"]


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


# ------------------------------------------------------------------------------------------ input checks
def as_grey(img: np.ndarray, name: str) -> np.ndarray:
    """(H, W) float32 from an (H, W) or (H, W, 3) RGB image of any real dtype (RGB: :func:`rangekit.image.to_grey`)."""
    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 3:
        a = to_grey(a)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim != 2:
        raise InputError(f"{name} image must be (H, W) grey or (H, W, 3) RGB, found shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating)) or a.dtype == np.bool_:
        raise InputError(f"{name} image must be an integer or float array, found dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _pair(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    L, R = as_grey(left, "left"), as_grey(right, "right")
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
    a = as_grey(img, "census")
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
    L, R = _pair(left_rect, right_rect)
    min_d, D = _search_range(min_disparity, num_disparities, L.shape[1])
    # Census codes; the Hamming cost, the aggregation over the paths (S(p, d) = sum_r L_r(p, d)),
    # winner-take-all and the left-right check run fused in rangekit.stereo._sgm, row by row.
    cl, cr = census_transform(L, window), census_transform(R, window)
    H, W = L.shape
    disp = np.empty((H, W), np.float32)
    conf = np.empty((H, W), np.float32)
    _sgm.sgm_match(cl, cr, min_d, D, np.int16(window[0] * window[1] - 1), np.int16(P1), np.int16(P2), paths == 8,
                   float(uniqueness), _SUBPIXEL[subpixel], int(lr_max_diff), disp, conf)
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
