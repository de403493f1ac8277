"""Projector coordinates of board corners by local homographies (Moreno and Taubin, "Simple, accurate, and
robust projector-camera calibration", 3DIMPVT 2012, section 3).

A board is a plane, so near a corner the map from camera pixels to the projector pixels they see is a
homography (up to the lenses' distortion, which is smooth over a window of a few squares' tenths). For each
corner found at subpixel camera position ``q`` the homography ``H`` is fitted over the decoded (proj_col,
proj_row) of the camera pixels of a ``(2 radius + 1)^2`` window around it, and the corner's projector
coordinates are ``H q`` (their eq. 2-3). Pixels the decoder masked (NaN) are left out; those it decoded wrong
(an unwrapping error, a pixel on the board's edge seeing the background) are removed by iteratively
reweighted least squares:

1. each window in normalised coordinates: camera pixels as offsets from ``q`` over ``radius``, projector
   coordinates as offsets from their median over their median distance to it;
2. two rounds of an affine fit, then four of the homography (DLT: the smallest eigenvector of the weighted
   9 x 9 normal matrix, weights divided by the squared denominator so the algebraic error stands for the
   transfer error), each round's weights Tukey's biweight of the transfer error in projector pixels (scale
   1.4826 x the median error, floored at 0.02 px; c = 4.685 scales);
3. the estimate ``H q``, NaN where fewer than ``min_pixels`` pixels keep a weight or where a quadrant of the
   window about ``q`` holds fewer than ``min_pixels / 8`` of them (the corner outside the decoded area, as at
   the edge of the projector's light: an estimate there would be an extrapolation).

All corners are solved at once: (n, 9, 9) normal matrices and one batched eigen-decomposition per round.
``std`` is the standard error of the estimate taken as that of a mean, each axis's RMS transfer error of the
kept pixels over the square root of their number (the fit is centred on the corner, where a homography's
value is nearly its constant term).

Frames: camera pixels (pixel centres at integers, u the column), projector pixels the decoder's.
"""

from __future__ import annotations

import warnings
from contextlib import contextmanager

import numpy as np

from rangekit.calib.projector import CornerFit

__all__ = ["local_homography_coords"]

_AFFINE_ROUNDS = 2
_TUKEY_C = 4.685
_MIN_SCALE_PX = 0.02


def local_homography_coords(proj_col: np.ndarray, proj_row: np.ndarray, uv: np.ndarray, *, radius: int = 10,
                            min_pixels: int = 50, iterations: int = 4) -> CornerFit:
    """Projector coordinates at subpixel camera points from robust local homographies (module doc).

    Parameters
    ----------
    proj_col, proj_row : (H, W) float ndarray
        Decoded projector column and row of each camera pixel, projector pixels; NaN where the decoder
        masked the pixel (both axes must be coded).
    uv : (n, 2) float ndarray
        Camera pixel positions of the corners (u the column; pixel centres at integers).
    radius : int
        Half-size of the square window, camera pixels (10: SLStudio's ``WINDOW_SIZE``; 21 x 21 pixels).
    min_pixels : int
        Fewest pixels that must keep a weight for an estimate (SLStudio's 50), an eighth of them in each
        quadrant about the corner.
    iterations : int
        Rounds of the reweighted homography fit after the affine ones.

    Returns
    -------
    CornerFit
        ``proj_uv`` (n, 2) projector pixels, NaN rows where not estimated (outside the projector's light,
        too few decoded pixels); ``std`` (n, 2) standard errors, projector pixels; ``n_pixels`` (n,) pixels kept.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    n = len(uv)
    if n == 0:
        return CornerFit(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64))
    height, width = proj_col.shape
    r = int(radius)
    off = np.arange(-r, r + 1)
    oy, ox = np.meshgrid(off, off, indexing="ij")
    px = np.rint(uv[:, :1]).astype(np.int64) + ox.ravel()[None]                 # (n, P) camera pixels
    py = np.rint(uv[:, 1:]).astype(np.int64) + oy.ravel()[None]
    inside = (px >= 0) & (px < width) & (py >= 0) & (py < height)
    pxc, pyc = np.clip(px, 0, width - 1), np.clip(py, 0, height - 1)
    col = proj_col[pyc, pxc].astype(np.float64)
    row = proj_row[pyc, pxc].astype(np.float64)
    valid = inside & np.isfinite(col) & np.isfinite(row)
    x, y = (px - uv[:, :1]) / r, (py - uv[:, 1:]) / r                           # step 1: normalised camera
    with np.errstate(invalid="ignore"), _quiet_all_nan():
        mc = np.nanmedian(np.where(valid, col, np.nan), axis=1, keepdims=True)
        mr = np.nanmedian(np.where(valid, row, np.nan), axis=1, keepdims=True)
        spread = np.nanmedian(np.where(valid, np.hypot(col - mc, row - mr), np.nan), axis=1, keepdims=True)
    mc, mr = np.nan_to_num(mc), np.nan_to_num(mr)
    s = np.where(np.isfinite(spread) & (spread > 0), spread, 1.0)
    X = np.where(valid, (col - mc) / s, 0.0)
    Y = np.where(valid, (row - mr) / s, 0.0)
    w0 = valid.astype(np.float64)
    w = w0.copy()
    one, zero = np.ones_like(x), np.zeros_like(x)
    affine = np.stack([x, y, one], axis=2)                                     # (n, P, 3)
    dlt_x = np.stack([x, y, one, zero, zero, zero, -X * x, -X * y, -X], axis=2)  # (n, P, 9)
    dlt_y = np.stack([zero, zero, zero, x, y, one, -Y * x, -Y * y, -Y], axis=2)
    h = np.zeros((n, 3, 3))
    for it in range(_AFFINE_ROUNDS + iterations):
        if it < _AFFINE_ROUNDS:                                                 # step 2: affine rounds
            N = np.einsum("npi,np,npj->nij", affine, w, affine) + 1e-12 * np.eye(3)
            b = np.einsum("npi,np,npk->nik", affine, w, np.stack([X, Y], axis=2))
            a = np.linalg.solve(N, b)                                           # (n, 3, 2)
            h = np.concatenate([a.transpose(0, 2, 1), np.tile([[[0.0, 0.0, 1.0]]], (n, 1, 1))], axis=1)
        else:                                                                   # then the homography (DLT)
            M = np.einsum("npi,np,npj->nij", dlt_x, w, dlt_x) + np.einsum("npi,np,npj->nij", dlt_y, w, dlt_y)
            h = np.linalg.eigh(M)[1][:, :, 0].reshape(n, 3, 3)
        den, ex, ey = _transfer(h, x, y, X, Y)
        err = np.hypot(ex, ey) * s                                              # projector pixels
        with _quiet_all_nan():
            scale = np.maximum(1.4826 * np.nanmedian(np.where(w > 0, err, np.nan), axis=1, keepdims=True),
                               _MIN_SCALE_PX)
        c = _TUKEY_C * np.nan_to_num(scale, nan=_MIN_SCALE_PX)
        tukey = np.where(err < c, (1 - (err / c) ** 2) ** 2, 0.0)
        w = w0 * tukey / np.maximum(den * den, 1e-12)
    kept = (w > 0) & valid                                                      # step 3
    n_kept = kept.sum(axis=1)
    quadrants = [np.sum(kept & (sx * x >= 0) & (sy * y >= 0), axis=1) for sx in (-1, 1) for sy in (-1, 1)]
    surrounded = np.min(quadrants, axis=0) >= min_pixels / 8
    with np.errstate(divide="ignore", invalid="ignore"):
        est = np.column_stack([h[:, 0, 2] / h[:, 2, 2], h[:, 1, 2] / h[:, 2, 2]]) * s + np.hstack([mc, mr])
        rms = np.sqrt(np.stack([np.sum(np.where(kept, ex * ex, 0.0), axis=1),
                                np.sum(np.where(kept, ey * ey, 0.0), axis=1)], axis=1) / np.maximum(n_kept, 1)[:, None])
        std = rms * s / np.sqrt(np.maximum(n_kept, 1))[:, None]
    bad = (n_kept < min_pixels) | ~surrounded | ~np.all(np.isfinite(est), axis=1)
    est[bad] = np.nan
    std[bad] = np.nan
    return CornerFit(proj_uv=est, std=std, n_pixels=n_kept)


def _transfer(h: np.ndarray, x: np.ndarray, y: np.ndarray, X: np.ndarray, Y: np.ndarray):
    """(den, ex, ey): the homographies ``h`` (n, 3, 3) at normalised camera points (n, P), their denominator and
    transfer errors against (X, Y), normalised projector units."""
    den = h[:, 2, 0, None] * x + h[:, 2, 1, None] * y + h[:, 2, 2, None]
    safe = np.where(np.abs(den) > 1e-12, den, 1e-12)
    ex = (h[:, 0, 0, None] * x + h[:, 0, 1, None] * y + h[:, 0, 2, None]) / safe - X
    ey = (h[:, 1, 0, None] * x + h[:, 1, 1, None] * y + h[:, 1, 2, None]) / safe - Y
    return den, ex, ey


@contextmanager
def _quiet_all_nan():
    """numpy's "All-NaN slice" warning silenced: a corner whose window holds no decoded pixel is NaN anyway."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="All-NaN slice encountered", category=RuntimeWarning)
        yield
