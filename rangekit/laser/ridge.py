"""Steger's ridge detector (C. Steger, "An unbiased detector of curvilinear structures", PAMI 1998) for a
laser line of any slant or curvature: subpixel points along the line's normal.

The difference image is smoothed with a Gaussian of std ``sigma`` (cv2, derivative-of-Gaussian filters
for the gradient and the Hessian). At every pixel where the smoothed image S is brighter than
``min_contrast`` times its noise, the Hessian of **ln S** (not of S, as in Steger) gives the normal n
(the eigenvector of its most negative eigenvalue lambda) and one Newton step along n gives the peak,
t = -(n . grad ln S) / lambda. For a Gaussian profile ln S is a parabola across the line, so the step is
exact wherever the pixel lies (Steger's Taylor step on S is biased by up to 0.04 px at half a pixel); and
ln of a brightness that changes along the line (albedo) adds nothing across it, so it neither tilts the
normal nor moves the point. The pixel keeps the point p + t n when it lies in the pixel's own square
(|t nx|, |t ny| <= 0.5), S bends down across the line by more than ``min_contrast`` times the noise of
that second derivative (Steger's curvature threshold: it drops the noise-driven tails), and the profile
is no wider than ``max_width``, and the profile's top (the Gaussian through the point) is at least
``min_contrast`` times the noise of the unsmoothed difference, like the row methods' peaks (the noise is
estimated on the whole image, mostly dark background, and the shot noise of lit surfaces is larger: their
smoothed noise forms faint ridges that pass the tests on S alone). Every pixel the line crosses gives one
point. Points within 2 sigma of
the border are dropped (the reflected border bends a slanted line). For a circle of radius R the
smoothed ridge moves inwards by about sigma_total^2 / (2 R).

Confidence: 1 / std(t) = S / (s^2 x noise x |first-derivative kernel|), s^2 = -1 / lambda the smoothed
profile's variance, combined with the point's offset along its normal from the points of its neighbouring
pixels (``_with_neighbours``), which catches what the noise model misses (line ends, speckle).
Height: the smoothed profile's top (below the raw peak by the factor s_line / s);
width: 4 sqrt(s^2 - sigma^2), the 1/e^2 width of the unsmoothed profile. Saturated: a full-scale sample
of the laser-on image in the pixel's 3 x 3 neighbourhood. Double: a row holding two clusters of points
more than ``gap`` px apart, the weaker above ``double_ratio`` times the stronger: all the row's points
are rejected (the line of a turntable scanner crosses each row once; pass double_ratio=None for lines
that legitimately cross a row twice).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from rangekit.errors import InputError

__all__ = ["ridge_peaks", "smoothing_kernels"]


def smoothing_kernels(sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Correlation kernels (2k+1,) float64, k = ceil(4 sigma), of the Gaussian of std ``sigma`` and of its
    first and second derivatives (sampled, the Gaussian's sum normalised to 1), for cv2.sepFilter2D."""
    k = max(1, int(math.ceil(4.0 * sigma)))
    x = np.arange(-k, k + 1, dtype=np.float64)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    g /= g.sum()
    g1 = x / sigma ** 2 * g                           # d/dx of the Gaussian, mirrored for correlation
    g2 = (x ** 2 / sigma ** 4 - 1.0 / sigma ** 2) * g
    return g, g1, g2 - g2.mean() * (g > 0)            # a second derivative sums to 0: flat areas give 0


def ridge_peaks(d, on, *, noise, sigma, min_contrast, double_ratio, gap, full_scale, max_width):
    """Steger points of the difference image ``d`` (H, W) float32 (see the module docstring); ``on`` is
    the laser-on image's used channel(s) for the saturation test. Returns a dict of LinePeaks' fields:
    points (N, 2), confidence, height, width (N,) and rejected (counts of points)."""
    if not np.isfinite(sigma) or sigma < 0.5:
        raise InputError(f"detect_peaks: the ridge method's sigma must be >= 0.5 px, found {sigma!r}")
    H, W = d.shape
    g, g1, g2 = smoothing_kernels(sigma)
    dnorm = float(np.linalg.norm(g1) * np.linalg.norm(g))

    def corr(img, k):                                 # cv2 correlates; a 1D filter2D beats sepFilter2D
        return cv2.filter2D(img, cv2.CV_32F, k.astype(np.float32), borderType=cv2.BORDER_REFLECT)

    Xg, Xg1, Xg2 = (corr(d, k[None, :]) for k in (g, g1, g2))   # along rows, over the whole image
    S = corr(Xg, g[:, None])
    s_noise = noise * float(np.linalg.norm(g)) ** 2
    bright = S > min_contrast * s_noise
    margin = max(1, int(math.ceil(2.0 * sigma)))     # the reflected border bends a slanted line
    bright[:margin, :] = bright[-margin:, :] = False
    bright[:, :margin] = bright[:, -margin:] = False
    y, x = np.nonzero(bright)
    c = S[y, x].astype(np.float64)
    # along columns only at the bright pixels (the same reflected border as cv2's)
    rows = y[:, None] + np.arange(-(g.size // 2), g.size // 2 + 1)
    rows = np.clip(np.where(rows < 0, -rows - 1, np.where(rows >= H, 2 * H - 1 - rows, rows)), 0, H - 1)
    xc = x[:, None]
    cg, cg1 = Xg[rows, xc].astype(np.float64), Xg1[rows, xc].astype(np.float64)
    rx, ry, ryy = cg1 @ g, cg @ g1, cg @ g2
    rxx, rxy = Xg2[rows, xc].astype(np.float64) @ g, cg1 @ g1
    gx, gy = rx / c, ry / c                           # the gradient and Hessian of ln S
    hxx, hyy, hxy = rxx / c - gx * gx, ryy / c - gy * gy, rxy / c - gx * gy
    half_tr = 0.5 * (hxx + hyy)
    root = np.sqrt((0.5 * (hxx - hyy)) ** 2 + hxy ** 2)
    lam, mu = half_tr - root, half_tr + root          # across the line (most negative), along it
    theta = 0.5 * np.arctan2(2.0 * hxy, hxx - hyy)    # direction of mu's eigenvector (along the line)
    nx, ny = -np.sin(theta), np.cos(theta)            # the normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -(gx * nx + gy * ny) / lam                # Newton on ln S: exact for a Gaussian profile
        s2 = -1.0 / lam                               # the smoothed profile's variance along n
    # S itself bends down across the line, by more than min_contrast x the noise of that second derivative
    # (Steger's threshold on the curvature): in a line's tail, where S is a few DN, ln S is noise-driven
    curv_noise = noise * float(np.linalg.norm(g2) * np.linalg.norm(g))
    concave = rxx * nx * nx + 2.0 * rxy * nx * ny + ryy * ny * ny < -min_contrast * curv_noise
    keep = (concave & (lam < 0) & (np.abs(lam) > np.abs(mu)) & (np.abs(t * nx) <= 0.5) & (np.abs(t * ny) <= 0.5)
            & (s2 - sigma ** 2 <= (0.5 * max_width) ** 2))
    y, x, t, nx, ny, c, s2 = (v[keep] for v in (y, x, t, nx, ny, c, s2))
    height = c * np.exp(0.5 * t ** 2 / s2)            # the Gaussian's top
    width = 4.0 * np.sqrt(np.maximum(s2 - sigma ** 2, 0.0))
    conf = c / (s2 * noise * dnorm)                   # 1 / std(t), t = s2 x (n . grad S) / S
    points = np.column_stack([x + t * nx, y + t * ny])
    rejected = {"weak": 0, "saturated": 0, "double": 0, "edge": 0}
    # the profile's top over the noise, the row methods' test: the smoothed-image tests above assume white
    # noise of the estimated std, but on lit surfaces shot noise makes it 2-4x larger than the dark
    # background's, and smoothed noise there forms faint ridges (27,000 of 44,000 points on simulated frames)
    good = height >= min_contrast * noise
    rejected["weak"] = int((~good).sum())
    if full_scale is not None and good.any():
        oy = np.clip(y[good, None] + np.repeat(np.arange(-1, 2), 3), 0, H - 1)
        ox = np.clip(x[good, None] + np.tile(np.arange(-1, 2), 3), 0, W - 1)
        nb = on[oy, ox]
        sat = np.zeros_like(good)
        sat[good] = nb.max(axis=tuple(range(1, nb.ndim))) >= full_scale
        rejected["saturated"] = int(sat.sum())
        good &= ~sat
    if double_ratio is not None and good.any():
        dbl = np.zeros_like(good)
        dbl[good] = _double_rows(y[good], x[good], height[good], gap, double_ratio)
        rejected["double"] = int((dbl & good).sum())
        good &= ~dbl
    conf = _with_neighbours(points[good], np.column_stack([nx, ny])[good], y[good], x[good], conf[good], (H, W))
    return dict(points=points[good], confidence=conf, height=height[good], width=width[good], rejected=rejected)


def _with_neighbours(p, n, y, x, conf, shape) -> np.ndarray:
    """The confidence with each point's disagreement with the points of its 8 neighbouring pixels (a line
    crossing a pixel gives one point per pixel, so they are its neighbours along the line): r = the mean
    of n . (p - p_j), the offset along the point's normal n from the neighbours (0 on a straight line,
    wherever along it they are), combined as 1 / sqrt(std^2 + r^2 / (1 + 1/k)) for k neighbours (noise
    alone gives r that variance for equal stds). No neighbour: std alone."""
    H, W = shape
    index = np.full((H + 2, W + 2), -1, np.int32)
    index[y + 1, x + 1] = np.arange(len(y))
    dy, dx = np.divmod(np.delete(np.arange(9), 4), 3)
    nb = index[y[:, None] + dy, x[:, None] + dx]          # (N, 8) neighbour point ids, -1 none (1-padded)
    has = nb >= 0
    k = has.sum(axis=1)
    diff = p[:, None, :] - p[np.maximum(nb, 0)]
    off = np.where(has, np.einsum("nkj,nj->nk", diff, n), 0.0).sum(axis=1) / np.maximum(k, 1)
    r2 = np.where(k > 0, off ** 2 / (1.0 + 1.0 / np.maximum(k, 1)), 0.0)
    return 1.0 / np.sqrt(1.0 / conf ** 2 + r2)


def _double_rows(y, x, height, gap, ratio) -> np.ndarray:
    """(N,) bool: the point's row holds two clusters of points (runs with gaps > ``gap`` px between
    them) and the weaker cluster's top is above ``ratio`` times the row's strongest."""
    order = np.lexsort((x, y))
    ys, xs, hs = y[order], x[order], height[order]
    new_row = np.r_[True, ys[1:] != ys[:-1]]
    new_cluster = new_row | np.r_[False, (xs[1:] - xs[:-1]) > gap]
    cstart = np.flatnonzero(new_cluster)
    ctop = np.maximum.reduceat(hs, cstart)
    crow = ys[cstart]
    rstart = np.r_[True, crow[1:] != crow[:-1]]
    rtop = np.maximum.reduceat(ctop, np.flatnonzero(rstart))
    row_id = np.cumsum(rstart) - 1
    strong = ctop >= ratio * rtop[row_id]
    n_strong = np.bincount(row_id, weights=strong)
    dbl_sorted = (n_strong[row_id] > 1)[np.cumsum(new_cluster) - 1]
    out = np.empty_like(dbl_sorted)
    out[order] = dbl_sorted
    return out
