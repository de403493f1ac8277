"""Subpixel peaks of a laser line in a laser-on minus laser-off image (Fusiello 13.2.4).

``detect_peaks(on, off)`` finds where the sheet of light crosses the image, to a fraction of a pixel,
with a confidence per peak and the reason every rejected row was rejected. Methods:

- ``"gaussian"`` (default): per row, a Gaussian fitted about the argmax by weighted least squares on the
  log of the samples within about 1.5 profile stds (at least 5 samples;
  :mod:`rangekit.laser.profile_fit`): exact for a Gaussian profile, and over five samples about half
  the noise-driven error of the three-point fit through m - 1, m, m + 1;
- ``"com"``: per row, the centre of mass of ``difference - 3 noise`` (clipped at 0) in a ``window``
  around the argmax (what Horus does; unbiased over all subpixel phases but locks towards pixel centres);
- ``"ridge"``: Steger's line detector (1998) in :mod:`rangekit.laser.ridge`, for slanted and curved
  lines: it returns points along the line's normal, possibly several per row;
- ``"argmax"``: the integer column of the row maximum, the baseline the others are measured against.

Input: ``on`` and ``off`` (H, W) grey or (H, W, 3) RGB, any integer or float dtype; the difference is
taken in float32. ``channel``: None or ``"white"`` use grey (RGB through :func:`rangekit.image.to_grey`,
the mean of the channels); ``"red"``, ``"green"``, ``"blue"`` use that channel only. That channel alone
(not the channel minus the mean of the others): after the laser-off subtraction there is no ambient
light left to cancel, the other channels would only add their noise, and a camera whose red laser
leaks into green would lose signal.

Output: :class:`LinePeaks`, points ``(u, v)`` in pixels with pixel centres at integers (u the column,
v the row). Rejections (per row for the row methods, counted for all):

- **weak**: the peak is less than ``min_contrast`` times the noise (no line in the row);
- **saturated**: one of the three samples at the peak is at full scale in the laser-on image (a clipped,
  flat top biases every fit). Rejected: lower the laser power or the exposure;
- **double**: the row holds a second peak, at least ``window`` columns away, above ``double_ratio``
  times the first (an interreflection or a second laser). Both are rejected: the stronger one is not
  always the direct light (a specular interreflection can outshine a dark surface), and a point on the
  wrong surface is worse than a missing one;
- **edge**: the peak is on the first or last column (no sample on one side).

``confidence`` is the inverse of the peak position's predicted standard deviation (1/px): first-order
propagation of the image noise through the method's formula (it grows with the peak height over the
noise and falls with the line's width), and for the row methods combined with the peak's disagreement
with the rows above and below (a line is smooth over three rows; see ``_with_neighbours``), which the
noise model alone misses (speckle, line ends, interreflections). The noise is estimated from the image
itself (a robust spread of horizontal pixel differences, which the line barely touches).

``require_peaks(peaks, frame)`` raises :class:`~rangekit.errors.DecodeError` naming the frame when too
few peaks were found, saying why (nothing lit, saturated, double): the scan calls it so that a frame
without a laser line is never a silent empty profile.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rangekit.errors import DecodeError, InputError
from rangekit.image import to_grey
from rangekit.laser.profile_fit import fit_gaussian_rows
from rangekit.laser.ridge import ridge_peaks

__all__ = ["LinePeaks", "detect_peaks", "smooth_along", "require_peaks", "laser_difference", "estimate_noise",
           "METHODS",
           "STATUS_OK", "STATUS_WEAK", "STATUS_SATURATED", "STATUS_DOUBLE", "STATUS_EDGE", "STATUS_NAMES"]

METHODS = ("gaussian", "com", "ridge", "argmax")
STATUS_OK, STATUS_WEAK, STATUS_SATURATED, STATUS_DOUBLE, STATUS_EDGE = 0, 1, 2, 3, 4
STATUS_NAMES = ("ok", "weak", "saturated", "double", "edge")
_CHANNELS = {"red": 0, "green": 1, "blue": 2}
#: quantisation noise of one count (std of a uniform step), the floor of the noise estimate
_QUANTUM = 1.0 / np.sqrt(12.0)


@dataclass(frozen=True, eq=False)
class LinePeaks:
    """The laser line's peaks in one frame.

    ``points`` (N, 2) float64 (u, v) in pixels, pixel centres at integers, accepted peaks only;
    ``confidence`` (N,) 1/px, the inverse of the predicted position std; ``height`` (N,) the peak above
    the laser-off image in the input's units (DN; the smoothed profile's height for ``ridge``);
    ``width`` (N,) the profile's 1/e^2 full width in px (NaN for ``argmax``); ``rows`` (N,) int64 the
    row of each peak for the row methods, None for ``ridge``; ``status`` (H,) int8 per row for the row
    methods (``STATUS_*``), None for ``ridge``; ``rejected`` counts per reason ({"weak", "saturated",
    "double", "edge"}: rows, or points/rows for ``ridge``); ``noise`` the estimated noise std of the
    difference image (DN); ``max_contrast`` the largest difference in the frame over ``noise``;
    ``shape`` (H, W); ``method``.
    """

    points: np.ndarray
    confidence: np.ndarray
    height: np.ndarray
    width: np.ndarray
    rows: np.ndarray | None
    status: np.ndarray | None
    rejected: dict
    noise: float
    max_contrast: float
    shape: tuple
    method: str

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def columns(self) -> np.ndarray:
        """(H,) float64: the subpixel column of each row's peak, NaN where none (row methods only)."""
        if self.rows is None:
            raise InputError("LinePeaks.columns: the ridge method has no one-column-per-row result; use .points")
        out = np.full(self.shape[0], np.nan)
        out[self.rows] = self.points[:, 0]
        return out


def laser_difference(on, off=None, channel: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(difference (H, W) float32 = on - off in the chosen channel, on's channel(s) used (H, W) or
    (H, W, 3), for the saturation test). See the module docstring for ``channel``."""
    on = np.asarray(on)
    if on.ndim not in (2, 3) or (on.ndim == 3 and on.shape[2] != 3) or min(on.shape[:2]) < 3:
        raise InputError(f"detect_peaks: the laser-on image must be (H, W) grey or (H, W, 3) RGB with H, W >= 3, "
                         f"found shape {on.shape}")
    if not (np.issubdtype(on.dtype, np.integer) or np.issubdtype(on.dtype, np.floating)):
        raise InputError(f"detect_peaks: the laser-on image must be of an integer or float dtype, found {on.dtype}")
    if off is not None:
        off = np.asarray(off)
        if off.shape != on.shape:
            raise InputError(f"detect_peaks: the laser-off image must have the laser-on image's shape {on.shape}, "
                             f"found {off.shape}")
    if channel is not None and channel != "white" and channel not in _CHANNELS:
        raise InputError(f"detect_peaks: channel must be None, 'white', 'red', 'green' or 'blue', found {channel!r}")
    if on.ndim == 3 and channel in _CHANNELS:
        on = on[..., _CHANNELS[channel]]
        off = None if off is None else off[..., _CHANNELS[channel]]
    if on.ndim == 3:
        d = to_grey(on) if off is None else to_grey(on) - to_grey(off)
    else:
        d = on.astype(np.float32) if off is None else np.subtract(on, off, dtype=np.float32)
    return d, on


def estimate_noise(d: np.ndarray, *, row_step: int = 8) -> float:
    """Robust noise std (input units) of a difference image: from horizontal differences of every
    ``row_step``-th row, the RMS of those within 4 robust sigmas of zero (a line or an edge is a few
    outliers); never below the quantisation noise of one count (0.29)."""
    sub = d[::max(1, row_step)]
    g = np.abs(np.diff(sub, axis=1)).ravel()
    if g.size == 0:
        return float(_QUANTUM)
    k = g.size // 2
    # A full sort, not np.partition: integer-valued differences hold few distinct values, and introselect
    # on such ties is ~15x slower than sorting (23 ms against 1.5 ms for one 1280x1024 frame).
    mad = float(np.sort(g)[k])
    s0 = max(1.4826 * mad / np.sqrt(2.0), _QUANTUM)
    inl = g[g <= 4.0 * np.sqrt(2.0) * s0]
    s = float(np.sqrt(np.mean(inl.astype(np.float64) ** 2) / 2.0)) if inl.size else s0
    return max(s / 0.9985, float(_QUANTUM))   # 0.9985: the RMS of a normal truncated at 4 sigma


def _full_scale(on: np.ndarray, saturation):
    if saturation is not None:
        return float(saturation)
    if np.issubdtype(on.dtype, np.integer):
        return float(np.iinfo(on.dtype).max)
    return None


def detect_peaks(on, off=None, *, method: str = "gaussian", channel: str | None = None, window: int = 9,
                 min_contrast: float = 6.0, double_ratio: float | None = 0.5, saturation: float | None = None,
                 sigma: float = 1.5, along: int = 0, mask: np.ndarray | None = None) -> LinePeaks:
    """The laser line's subpixel peaks in ``on - off`` (see the module docstring).

    ``window`` (px, >= 3, at least the line's 1/e^2 width): the centre-of-mass window (window // 2 either
    side of the argmax) and the distance beyond which a second peak makes a row double (ridge: the gap
    between two clusters of points in a row); ``min_contrast``: the smallest accepted
    peak height over the noise std (ridge: also the first filter on the smoothed difference, about 5x
    less noisy at sigma 1.5); ``double_ratio``: a second peak above this fraction of the
    first rejects the row (None: no test); ``saturation``: the full-scale value of the laser-on image
    (default: the dtype's maximum for integer images, 255 or 65535: pass 4095 for a 12-bit camera stored
    in uint16; no test for float images); ``sigma``: the ridge method's smoothing (px); ``along`` (row
    methods, 0 <= along <= 10; 0: off): smooth the columns along the line over ``along`` rows either side
    (see :func:`smooth_along`): on simulated frames ``along=3`` takes the Gaussian fit from 0.070 to
    0.044 px RMS, at the price of detail along the line finer than ~2 along + 1 rows. ``mask``: (H, W)
    bool, the pixels where the line may be (False: ignored, e.g. where the laser's plane lies below the
    turntable top, :func:`rangekit.laser.triangulate.plane_region`), so a second line there does not
    make a row double.
    """
    if method not in METHODS:
        raise InputError(f"detect_peaks: method must be one of {', '.join(METHODS)}, found {method!r}")
    if int(window) != window or window < 3:
        raise InputError(f"detect_peaks: window must be a whole number of pixels >= 3, found {window!r}")
    if not np.isfinite(min_contrast) or min_contrast <= 0:
        raise InputError(f"detect_peaks: min_contrast must be a finite number > 0, found {min_contrast!r}")
    if double_ratio is not None and not 0 < double_ratio <= 1:
        raise InputError(f"detect_peaks: double_ratio must be in (0, 1] or None, found {double_ratio!r}")
    if int(along) != along or not 0 <= along <= 10:
        raise InputError(f"detect_peaks: along must be a whole number of rows in 0..10, found {along!r}")
    d, on_used = laser_difference(on, off, channel)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != d.shape or m.dtype != bool:
            raise InputError(f"detect_peaks: mask must be a bool array of the image's shape {d.shape}, found "
                             f"{m.dtype} {m.shape}")
    if np.issubdtype(np.asarray(on).dtype, np.floating) and not np.isfinite(d).all():
        raise InputError("detect_peaks: the laser-on/off images hold NaN or infinite values; expected finite "
                         f"intensities, found {int(np.count_nonzero(~np.isfinite(d)))} non-finite pixels")
    noise = estimate_noise(d)   # on the whole image: the masked-out pixels are noise samples too
    if mask is not None:
        d = np.where(m, d, np.float32(0))
    full = _full_scale(np.asarray(on), saturation)
    if method == "ridge":
        found = ridge_peaks(d, on_used, noise=noise, sigma=sigma, min_contrast=min_contrast,
                            double_ratio=double_ratio, gap=int(window), full_scale=full,
                            max_width=2.0 * window)
        return LinePeaks(**found, rows=None, status=None, noise=noise, max_contrast=float(d.max() / noise),
                         shape=d.shape, method="ridge")
    peaks = _row_peaks(d, on_used, method=method, noise=noise, half=int(window) // 2, min_contrast=min_contrast,
                       double_ratio=double_ratio, full_scale=full)
    return smooth_along(peaks, int(along)) if along and method != "argmax" else peaks


def _row_peaks(d, on, *, method, noise, half, min_contrast, double_ratio, full_scale) -> LinePeaks:
    H, W = d.shape
    r = np.arange(H)
    m = d.argmax(axis=1)
    peak = d[r, m]
    status = np.where(peak < min_contrast * noise, STATUS_WEAK, STATUS_OK).astype(np.int8)
    status[(status == STATUS_OK) & ((m == 0) | (m == W - 1))] = STATUS_EDGE
    mc = np.clip(m, 1, W - 2)
    if full_scale is not None:
        top = on[r[:, None], mc[:, None] + np.arange(-1, 2)]
        sat = (top.max(axis=tuple(range(1, top.ndim))) >= full_scale)
        status[(status == STATUS_OK) & sat] = STATUS_SATURATED
    if double_ratio is not None:
        status[(status == STATUS_OK) & _second_peak_above(d, m, half, double_ratio * peak)] = STATUS_DOUBLE
    ok = status == STATUS_OK
    rows = r[ok]
    if method == "argmax":
        u = m[ok].astype(np.float64)
        width = np.full(u.shape, np.nan)
        conf = np.full(u.shape, np.sqrt(12.0))   # a uniform error over one pixel
        height = peak[ok].astype(np.float64)
    elif method == "gaussian":
        u, height, width, conf = fit_gaussian_rows(d, rows, mc[ok], noise)
    else:
        u, height, width, conf = _centre_of_mass(d, rows, m[ok], half, noise)
    if method != "argmax":
        conf = _with_neighbours(u, rows, conf, H)
    rejected = {name: int(np.count_nonzero(status == code)) for code, name in enumerate(STATUS_NAMES) if code}
    points = np.column_stack([u, rows.astype(np.float64)])
    return LinePeaks(points=points, confidence=conf, height=height, width=width, rows=rows, status=status,
                     rejected=rejected, noise=noise, max_contrast=float(peak.max() / noise), shape=(H, W),
                     method=method)


def _with_neighbours(u, rows, conf, H) -> np.ndarray:
    """The confidence with the row's disagreement with its neighbours: 1 / sqrt(std^2 + r^2 / 1.5), r the
    peak's column minus the mean of the peaks in rows v - 1 and v + 1 (noise alone gives r a variance of
    1.5 std^2 for equal stds), or r^2 / 2 with the one neighbour there is; no neighbour: std alone. A
    smooth line changes little over three rows, so r catches what the noise model does not (speckle,
    a line end, an interreflection's shoulder, a tail of a wrong peak): on simulated frames the worst
    decile by confidence then holds ~95% of the errors over 3x the RMS (~40% with the noise model alone)."""
    col = np.full(H + 2, np.nan)
    col[rows + 1] = u
    up, down = col[rows], col[rows + 2]
    both = 0.5 * (up + down)
    one = np.where(np.isfinite(up), (u - up) ** 2 / 2.0, np.where(np.isfinite(down), (u - down) ** 2 / 2.0, 0.0))
    r2 = np.where(np.isfinite(both), (u - both) ** 2 / 1.5, one)
    return 1.0 / np.sqrt(1.0 / conf ** 2 + r2)


def smooth_along(peaks: LinePeaks, along: int, *, max_residual: float = 0.4) -> LinePeaks:
    """Row peaks smoothed along the line: at each row whose ``along`` rows either side all hold a peak, a
    quadratic in the row fitted to the 2 along + 1 columns (a Savitzky-Golay filter) replaces the column,
    unless a column is more than ``max_residual`` px off that quadratic (a jump in depth, a line end, a
    wrong peak: the row keeps its own). The noise of the rows is independent, so it falls by the filter's
    factor (sqrt(1/3) at along = 3); the confidence is 1 / (that factor x the larger of the row's std and
    the columns' spread about the quadratic). A curve is kept to second order. ``along`` >= 2. Returns a
    new LinePeaks (row methods only)."""
    if peaks.rows is None:
        raise InputError("smooth_along: the ridge method's points are not one per row")
    if along < 2:
        return peaks                                    # a quadratic through 3 rows is the rows themselves
    x = np.arange(-along, along + 1, dtype=np.float64)
    A = np.stack([np.ones_like(x), x, x * x], axis=1)
    fit = np.linalg.pinv(A)                             # (3, 2 along + 1): the quadratic's coefficients
    col = np.full(peaks.shape[0] + 2 * along, np.nan)
    col[peaks.rows + along] = peaks.points[:, 0]
    win = np.lib.stride_tricks.sliding_window_view(col, 2 * along + 1)[peaks.rows]
    c = win @ fit.T
    r = win - c @ A.T
    ok = np.isfinite(r).all(axis=1)
    ok[ok] = np.abs(r[ok]).max(axis=1) <= max_residual
    points = peaks.points.copy()
    points[ok, 0] = c[ok, 0]
    # std: the filter's factor times the larger of the row's own std and the spread of the columns about
    # the quadratic (what the rows disagree by: speckle, noise the model underrates)
    spread2 = np.sum(r[ok] ** 2, axis=1) / (2 * along - 2)
    conf = peaks.confidence.copy()
    conf[ok] = 1.0 / np.sqrt(np.sum(fit[0] ** 2) * np.maximum(1.0 / conf[ok] ** 2, spread2))
    return replace(peaks, points=points, confidence=conf)


def _second_peak_above(d, m, half, level) -> np.ndarray:
    """(H,) bool: a sample more than ``half`` + 1 columns from the row's argmax ``m`` reaches ``level``.
    The samples near the argmax are set to -inf for one max and restored (no copy of the image)."""
    H, W = d.shape
    r = np.arange(H)[:, None]
    cols = np.clip(m[:, None] + np.arange(-half - 1, half + 2), 0, W - 1)
    kept = d[r, cols]
    d[r, cols] = -np.inf
    try:
        second = d.max(axis=1)
    finally:
        d[r, cols] = kept
    return second >= level


def _centre_of_mass(d, rows, m, half, noise, k_noise: float = 3.0):
    """Centre of mass of max(d - k_noise * noise, 0) over columns m - half .. m + half (clipped to the
    image); width 4 x the weights' standard deviation; std of u by propagating the noise."""
    W = d.shape[1]
    offs = np.arange(-half, half + 1)
    cols = m[:, None] + offs
    inside = (cols >= 0) & (cols < W)
    vals = d[rows[:, None], np.clip(cols, 0, W - 1)].astype(np.float64)
    w = np.where(inside, np.maximum(vals - k_noise * noise, 0.0), 0.0)
    s = w.sum(axis=1)
    s = np.where(s > 0, s, 1.0)
    mean_off = (w * offs).sum(axis=1) / s
    var = (w * (offs - mean_off[:, None]) ** 2).sum(axis=1) / s
    lit = w > 0
    std = noise * np.sqrt((lit * (offs - mean_off[:, None]) ** 2).sum(axis=1)) / s
    height = vals.max(axis=1)
    return m + mean_off, height, 4.0 * np.sqrt(var), 1.0 / np.maximum(std, 1e-9)


def require_peaks(peaks: LinePeaks, frame: str, *, min_points: int = 10) -> LinePeaks:
    """``peaks`` when it holds at least ``min_points`` peaks, else :class:`DecodeError` naming ``frame``
    (a file or a scan step) and why: nothing lit, a saturated line, or interreflections."""
    n = len(peaks)
    if n >= min_points:
        return peaks
    rej = {k: v for k, v in peaks.rejected.items() if v}
    why = []
    if rej.get("saturated"):
        why.append(f"{rej['saturated']} saturated (the line is clipped at full scale: lower the laser power or "
                   "the exposure)")
    if rej.get("double"):
        why.append(f"{rej['double']} with a double peak (interreflections or a second laser in view)")
    if not why:
        why.append(f"no laser line visible: the brightest laser-on minus laser-off difference is "
                   f"{peaks.max_contrast:.1f} times the noise ({peaks.noise:.2f}), the threshold for a peak is "
                   "min_contrast; is the laser on, pointed at the object, and the object in view?")
    unit = "rows" if peaks.rows is not None else "points"
    raise DecodeError(f"laser frame {frame}: found {n} line peaks ({peaks.method}), expected at least {min_points}; "
                      f"rejected {unit}: " + "; ".join(why))
