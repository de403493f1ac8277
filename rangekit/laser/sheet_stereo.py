"""Laser-sheet stereo (Fusiello 2024, 13.2.1 item 3): a sheet of light swept over the scene and seen by a
calibrated pair of cameras. The light only marks the points; the two cameras triangulate them, so the laser's
plane needs no calibration.

Per pair of frames (laser on minus laser off in each camera):

1. **Peaks.** Each image's subpixel line peaks, one per row (:func:`rangekit.laser.detect_peaks`, a row
   method), in distorted pixels.
2. **Rectification of points, not images.** Both sets of peaks are carried onto the rectified pair
   (:func:`rangekit.stereo.rectify.rectify_pixels`: the lens model's inverse, the rectifying rotation, the
   common intrinsics), where the epipolar line of a left point is the rectified row through it.
3. **The right line as a polyline.** Consecutive peaks of the right image are joined by a segment when they
   are on consecutive raw rows (no gap: a row without a peak is a shadow, an occlusion, a rejected row) and
   their columns differ by at most ``max_step`` pixels (more is a depth edge, not a continuous curve).
4. **Crossings.** Each left peak's rectified row ``v`` is met with the right polyline: every segment whose
   rows span ``v`` (half-open, so a crossing at a shared vertex counts once) gives the column ``u_r`` there,
   linearly interpolated. Only crossings with a disparity ``d = u_l - u_r`` inside the depth range
   (``min_depth`` .. ``max_depth`` metres, ``d = f B / z``) count. Exactly one: matched. None: unmatched (the
   right camera does not see that point of the line, or its line has a gap there). Several: ambiguous,
   refused (the right line folds back over the row; the nearer and the farther crossing are both possible).
5. **Triangulation.** ``z = f B / d`` in the rectified-left frame (:func:`rangekit.stereo.depth.disparity_points`),
   carried into the world.
6. **Off the sheet** (:func:`fit_sheet`). Where the true match is hidden from the right camera (an ear in front
   of the other) and another stretch of the line crosses the same epipolar line, the one crossing found is wrong,
   and nothing in the images tells: the point lands millimetres off the surface. The light sheet is planar, so
   the frame's matched points are fitted with a plane, refitted without the points far from it, and a point
   farther from it than ``OFF_SHEET_SIGMAS`` robust standard deviations (and than ``OFF_SHEET_FOOTPRINTS`` pixel
   footprints) is refused. The plane is measured from this frame's own points: nothing is calibrated, and a sheet
   that moves between frames (a hand-held laser) is as good as a fixed one. Points that do not fix a plane (fewer
   than ``MIN_SHEET_POINTS``, or on one straight line) are kept unchecked.
7. **Filling in** (optional, :func:`fill_from_sheet`). The left peaks the pair could not triangulate (the right
   camera does not see them, or their match was refused) are met with that fitted sheet, as one camera meets a
   calibrated plane (:func:`on_sheet`), where the sheet is known there to better than half the pair's scatter
   about it (:meth:`SheetPlane.std_at`).

Accuracy: a column error ``e`` px in either image moves the point along the left ray by about
``z e / (f sin(alpha))`` (``alpha`` the angle between the two rays), against ``z e / (f sin(phi))`` for one
camera and the laser's plane (``phi`` the angle between ray and plane): a pair converging as much as the camera
and the laser do is as accurate as the single camera, up to the second image's own peak noise (``sqrt(2)``).
Frames: points in the rig's world frame, metres; pixels (u, v) = (column, row), centres at integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.laser.peaks import LinePeaks
from rangekit.laser.plane_fit import tls_plane
from rangekit.laser.profile_filter import pixel_footprint
from rangekit.laser.triangulate import MIN_RAY_PLANE_ANGLE, triangulate_peaks
from rangekit.stereo.depth import disparity_points
from rangekit.stereo.rectify import Rectification, rectify, rectify_pixels

__all__ = ["SheetStereoPoints", "SheetPlane", "sheet_stereo", "match_sheet", "right_segments", "fit_sheet", "on_sheet",
           "fill_from_sheet", "OFF_SHEET_SIGMAS", "OFF_SHEET_FOOTPRINTS", "MIN_SHEET_POINTS"]

#: A matched point farther from its frame's sheet than this many robust standard deviations is off the sheet ...
OFF_SHEET_SIGMAS = 6.0
#: ... and farther than this many pixel footprints (distance / focal length) at the point.
OFF_SHEET_FOOTPRINTS = 1.0
#: Fewer matched points than this do not fix a frame's sheet (their points are kept unchecked).
MIN_SHEET_POINTS = 20


@dataclass(frozen=True, eq=False)
class SheetStereoPoints:
    """Laser-sheet stereo points of one pair of frames, one row per left peak.

    xyz : (N, 3) float64 world points, metres; NaN where the left peak was not matched.
    disparity : (N,) float64 rectified pixels (``u_left - u_right``); NaN where not matched.
    right_u : (N,) float64 the matched rectified right column; NaN where not matched.
    n_unmatched : left peaks whose rectified row meets no segment of the right line within the depth range.
    n_ambiguous : left peaks whose row meets it more than once (refused).
    n_invalid : left peaks that were NaN or whose pixel the lens model could not invert.
    n_off_sheet : matched left peaks refused because their point lies off the frame's light sheet (step 6).
    sheet : the frame's sheet fitted to the matched points (:class:`SheetPlane`; its ``plane`` None when they do not
        fix one), None when the check was not asked for.
    rect : the rectification used.
    """

    xyz: np.ndarray
    disparity: np.ndarray
    right_u: np.ndarray
    n_unmatched: int
    n_ambiguous: int
    n_invalid: int
    n_off_sheet: int
    sheet: SheetPlane | None
    rect: Rectification

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: the rows of ``xyz`` that hold a point."""
        return np.isfinite(self.xyz[:, 0])

    @property
    def points(self) -> np.ndarray:
        """(M, 3) the matched points only."""
        return self.xyz[self.valid]

    def __repr__(self) -> str:
        return (f"SheetStereoPoints({int(self.valid.sum())} of {len(self.xyz)} left peaks matched; "
                f"{self.n_unmatched} unmatched, {self.n_ambiguous} ambiguous, {self.n_off_sheet} off the sheet, "
                f"{self.n_invalid} invalid; "
                f"baseline {self.rect.baseline * 1e3:.1f} mm)")


@dataclass(frozen=True, eq=False)
class SheetPlane:
    """The plane of one frame's matched points (:func:`fit_sheet`).

    plane : (4,) ``[n, d]``, ``n . X + d = 0``, |n| = 1, world frame; None when the points do not fix one.
    on : (N,) bool over the points given: on the sheet (within the limit), or unchecked (no plane); NaN rows False.
    sigma : metres, the robust standard deviation of the points' distances from the plane (NaN without a plane).
    n_off : points refused as off the sheet.
    centroid : (3,) the mean of the points on it; axes : (2, 3) their principal directions in the plane, the
        longer first; spread : (2,) their standard deviations along them (metres); n_on : how many.
    """

    plane: np.ndarray | None
    on: np.ndarray
    sigma: float
    n_off: int
    centroid: np.ndarray | None = None
    axes: np.ndarray | None = None
    spread: np.ndarray | None = None
    n_on: int = 0

    def std_at(self, points: np.ndarray) -> np.ndarray:
        """(N,) metres: the standard deviation of the fitted plane's position at ``points`` (N, 3) along its
        normal, from the points' scatter about it (independent errors of std ``sigma``): ``sigma / sqrt(n) *
        sqrt(1 + (a1 / s1)^2 + (a2 / s2)^2)`` with ``a`` the offsets from the centroid along the axes. Small
        inside the fitted stretch, growing as a point lies away from it (an extrapolated tilt)."""
        if self.plane is None:
            return np.full(len(points), np.inf)
        a = (np.asarray(points, dtype=np.float64) - self.centroid) @ self.axes.T / self.spread
        return self.sigma / np.sqrt(self.n_on) * np.sqrt(1.0 + np.sum(a * a, axis=1))


def fit_sheet(xyz: np.ndarray, camera: PinholeCamera, *, k: float = OFF_SHEET_SIGMAS,
              min_footprints: float = OFF_SHEET_FOOTPRINTS, min_points: int = MIN_SHEET_POINTS,
              max_iterations: int = 10) -> SheetPlane:
    """The light sheet of one frame from its matched points ``xyz`` (N, 3) (NaN rows ignored), and which points
    lie on it (module doc, step 6): within ``k`` robust standard deviations (1.4826 x the median distance) and
    ``min_footprints`` pixel footprints of ``camera`` (the left one) of the plane.

    The plane: total least squares (:func:`rangekit.laser.plane_fit.tls_plane`) of all the points, then of those on
    it, until they do not change. Not least median of squares (:func:`~rangekit.laser.plane_fit.fit_plane`): wrong
    matches are a few points, while a profile is often more than half one straight stretch, which any plane
    through that stretch fits with a median of zero. Points on one straight line (the second principal spread
    not ten times the thickness, as ``fit_plane``'s test) fix no plane: ``plane`` None, every point kept."""
    P = np.asarray(xyz, dtype=np.float64)
    finite = np.isfinite(P).all(axis=1)
    unchecked = SheetPlane(None, finite, float("nan"), 0)
    if finite.sum() < min_points:
        return unchecked
    Q = np.where(finite[:, None], P, 0.0)
    floor = min_footprints * pixel_footprint(Q, camera)
    on = finite
    for _ in range(max(1, max_iterations)):
        plane, _, _ = tls_plane(P[on])
        r = np.abs(Q @ plane[:3] + plane[3])
        sigma = 1.4826 * float(np.median(r[on]))
        new = finite & (r <= np.maximum(k * sigma, floor))
        if new.sum() < min_points:
            return unchecked
        if np.array_equal(new, on):
            break
        on = new
    plane, _, centroid = tls_plane(P[on])
    _, s, Vt = np.linalg.svd(P[on] - centroid, full_matrices=False)
    spread = s / np.sqrt(on.sum())
    if not spread[1] > max(10.0 * spread[2], 1e-6 * spread[0]):   # tested on the points kept: outliers look thick
        return unchecked
    sigma = max(sigma, float(spread[2]), 1e-9)
    return SheetPlane(plane, on, sigma, int((finite & ~on).sum()), centroid, Vt[:2], spread[:2], int(on.sum()))


def on_sheet(uv: np.ndarray, camera: PinholeCamera, sheet: SheetPlane, *,
             max_std: float = 0.5) -> np.ndarray:
    """(N, 3) float64 world points of peaks ``uv`` (N, 2) of ``camera`` (either of the pair) met with the frame's
    fitted ``sheet`` (:func:`rangekit.laser.triangulate.triangulate_peaks`: the one ray-plane triangulation, its
    grazing and behind refusals); NaN where refused, and where the plane is known there less well than ``max_std``
    times ``sheet.sigma`` (:meth:`SheetPlane.std_at`: an extrapolation far from the points that fixed it). All NaN
    without a plane. For the peaks the other camera does not see, which the pair cannot triangulate."""
    uv = np.asarray(uv, dtype=np.float64)
    out = np.full((len(uv), 3), np.nan)
    if sheet.plane is None or len(uv) == 0:
        return out
    tri = triangulate_peaks(uv, camera, sheet.plane, min_angle=MIN_RAY_PLANE_ANGLE)
    ok = tri.valid
    ok[ok] = sheet.std_at(tri.xyz[ok]) <= max_std * sheet.sigma
    out[ok] = tri.xyz[ok]
    return out


def fill_from_sheet(res: SheetStereoPoints, left_uv: np.ndarray, left_cam: PinholeCamera, *,
                    max_std: float = 0.5) -> np.ndarray:
    """(N, 3) world points of the left peaks ``left_uv`` (N, 2) (those ``res`` was matched from) that the pair did
    not triangulate, each met with the frame's sheet fitted to the pair's points (``res.sheet``, :func:`on_sheet`);
    NaN where the pair matched the peak, where :func:`on_sheet` refuses it, and everywhere without a sheet (step
    7). Left peaks refused as off the sheet are filled too: the peak is on the line, its match was wrong."""
    uv = np.asarray(left_uv, dtype=np.float64)
    out = np.full((len(uv), 3), np.nan)
    if res.sheet is None or res.sheet.plane is None:
        return out
    todo = ~res.valid & np.isfinite(uv).all(axis=1)
    out[todo] = on_sheet(uv[todo], left_cam, res.sheet, max_std=max_std)
    return out


def right_segments(uv_rect: np.ndarray, rows: np.ndarray, uv_raw: np.ndarray, *,
                   max_step: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """The right line as segments: ((M, 2) float64, (M, 2) float64) rectified end points (u, v) of every segment
    joining two peaks on consecutive raw rows whose raw columns differ by at most ``max_step`` pixels.

    ``uv_rect`` (N, 2) the peaks' rectified pixels, ``rows`` (N,) their raw rows, ``uv_raw`` (N, 2) their raw
    pixels; NaN peaks join nothing."""
    order = np.argsort(rows, kind="stable")
    r, a, raw = np.asarray(rows)[order], uv_rect[order], uv_raw[order]
    ok = (np.diff(r) == 1) & (np.abs(np.diff(raw[:, 0])) <= max_step) \
        & np.isfinite(a[:-1]).all(axis=1) & np.isfinite(a[1:]).all(axis=1)
    return a[:-1][ok], a[1:][ok]


def match_sheet(left_uv: np.ndarray, right_uv: np.ndarray, right_rows: np.ndarray, left_cam: PinholeCamera,
                right_cam: PinholeCamera, *, rect: Rectification | None = None, max_step: float = 3.0,
                min_depth: float = 0.05, max_depth: float = 10.0, check_sheet: bool = True) -> SheetStereoPoints:
    """Triangulate left line peaks against the right camera's line (module doc, steps 2-6).

    Parameters
    ----------
    left_uv : (N, 2) the left image's peaks (u, v), distorted pixels; NaN rows give NaN.
    right_uv : (M, 2) the right image's peaks; ``right_rows`` (M,) int the raw row of each (one peak per row: a
        row method of :func:`rangekit.laser.detect_peaks`).
    left_cam, right_cam : the calibrated pair, posed in one world; the right camera on the left's +x side.
    rect : their rectification (default :func:`rangekit.stereo.rectify.rectify` of the pair): pass it to
        reuse it over many frames.
    max_step : pixels; consecutive right rows whose columns differ more are not joined.
    min_depth, max_depth : metres, the depth range (rectified-left z) crossings are looked for in.
    check_sheet : refuse the matches off the frame's light sheet (step 6; :func:`fit_sheet`'s defaults).

    Raises
    ------
    InputError : arrays of the wrong shape, a depth range that is not 0 < min_depth < max_depth, and
        (from :func:`rectify`) a pair that cannot be rectified: one optical centre, a vertical pair, the right
        camera on the left's -x side.
    """
    left_uv = np.asarray(left_uv, dtype=np.float64)
    right_uv = np.asarray(right_uv, dtype=np.float64)
    right_rows = np.asarray(right_rows)
    if left_uv.ndim != 2 or left_uv.shape[1] != 2 or right_uv.ndim != 2 or right_uv.shape[1] != 2:
        raise InputError(f"match_sheet: left_uv and right_uv must be (N, 2) arrays of (u, v) pixels, found shapes "
                         f"{left_uv.shape} and {right_uv.shape}")
    if right_rows.shape != (len(right_uv),) or not np.issubdtype(right_rows.dtype, np.integer):
        raise InputError(f"match_sheet: right_rows must be ({len(right_uv)},) integer rows, one per right peak, "
                         f"found {right_rows.dtype} {right_rows.shape}")
    if not (np.isfinite(min_depth) and np.isfinite(max_depth) and 0 < min_depth < max_depth):
        raise InputError(f"match_sheet: need 0 < min_depth < max_depth (metres), found {min_depth!r}, {max_depth!r}")
    if not (np.isfinite(max_step) and max_step > 0):
        raise InputError(f"match_sheet: max_step must be > 0 pixels, found {max_step!r}")
    rect = rect if rect is not None else rectify(left_cam, right_cam)
    ul = rectify_pixels(rect, left_cam, left_uv)
    n = len(ul)
    invalid = ~np.isfinite(ul).all(axis=1)
    a, b = right_segments(rectify_pixels(rect, right_cam, right_uv, right=True), right_rows, right_uv,
                          max_step=max_step)
    u_right = np.full(n, np.nan)
    count = np.zeros(n, dtype=np.int64)
    fb = rect.focal * rect.baseline
    if len(a) and n:
        lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
        order = np.argsort(lo, kind="stable")
        a, b, lo, hi = a[order], b[order], lo[order], hi[order]
        span = float((hi - lo).max())
        q_all = np.flatnonzero(~invalid)
        v = ul[q_all, 1]
        # Candidates: segments whose lower end lies in (v - span, v]; then those whose [lo, hi) holds v.
        i0 = np.searchsorted(lo, v - span, side="right")
        i1 = np.searchsorted(lo, v, side="right")
        k = i1 - i0
        q = np.repeat(np.arange(len(v)), k)
        s = i0[q] + (np.arange(q.size) - np.repeat(np.cumsum(k) - k, k))
        hit = (lo[s] <= v[q]) & (v[q] < hi[s])
        q, s = q[hit], s[hit]
        f = (v[q] - a[s, 1]) / (b[s, 1] - a[s, 1])
        u = a[s, 0] + f * (b[s, 0] - a[s, 0])
        d = ul[q_all[q], 0] - u
        inside = (d >= fb / max_depth) & (d <= fb / min_depth)
        q, u = q[inside], u[inside]
        count[q_all] = np.bincount(q, minlength=len(v))
        one = count[q_all[q]] == 1
        u_right[q_all[q[one]]] = u[one]
    matched = count == 1
    xyz = np.full((n, 3), np.nan)
    if matched.any():
        xyz[matched] = disparity_points(ul[matched, 0], ul[matched, 1], ul[matched, 0] - u_right[matched], rect)
    sheet = None
    if check_sheet:
        sheet = fit_sheet(xyz, left_cam)
        xyz[~sheet.on] = np.nan
        u_right[~sheet.on] = np.nan
    disparity = ul[:, 0] - u_right
    return SheetStereoPoints(xyz=xyz, disparity=disparity, right_u=u_right,
                             n_unmatched=int(((count == 0) & ~invalid).sum()), n_ambiguous=int((count > 1).sum()),
                             n_invalid=int(invalid.sum()), n_off_sheet=0 if sheet is None else sheet.n_off,
                             sheet=sheet, rect=rect)


def sheet_stereo(left: LinePeaks, right: LinePeaks, left_cam: PinholeCamera, right_cam: PinholeCamera,
                 **options) -> SheetStereoPoints:
    """:func:`match_sheet` of two frames' :class:`~rangekit.laser.peaks.LinePeaks` (row methods: ``gaussian``,
    ``com``, ``argmax``); ``options`` as there. Rows of the result follow ``left.points``."""
    for name, peaks, cam in (("left", left, left_cam), ("right", right, right_cam)):
        if peaks.rows is None:
            raise InputError(f"sheet_stereo: the {name} peaks come from the {peaks.method!r} method, which gives no "
                             "one peak per row; use a row method (gaussian, com, argmax)")
        if tuple(peaks.shape) != (cam.height, cam.width):
            raise InputError(f"sheet_stereo: the {name} peaks were found in a {peaks.shape[1]}x{peaks.shape[0]} image "
                             f"but camera {cam.name!r} is {cam.width}x{cam.height} (width x height)")
    return match_sheet(left.points, right.points, right.rows, left_cam, right_cam, **options)
