"""Laser-plane calibration from plane targets: the calibration board's poses and the turntable plate.

For each pose of a plane target (its frame's z = 0 plane, pose ``T_world_target`` from camera calibration)
the laser line's subpixel points in the camera image are back-projected (with the lens distortion,
``PinholeCamera.rays``) and intersected with the target's plane (:func:`rangekit.geometry.ray_plane_t`),
giving 3D points of the light sheet. Only points inside the target's extent are kept (outside it the
line lies on something else). The points of all poses are fitted to one plane
(:func:`rangekit.laser.plane_fit.fit_plane`: robust, with its residual).

Poses: each pose adds one line of the light sheet. One line does not fix the plane (it may turn about
the line); two distinct lines do (crossing or parallel), and more poses at varied tilts average the noise
(10 poses: see docs/laser.md). A pose is rejected, with its name and reason, when its line misses the
target (fewer than ``min_points`` points on it) or it has no points; it is never used silently. If the
lines of all used poses lie on one 3D line (the board moved only within its own plane, or one pose),
the plane is not determined: :class:`~rangekit.errors.CalibrationError`.

The turntable plate (``z_table = 0`` of ``T_world_table``, a disc) is one more target: the laser line on
the bare plate gives one line (the plate cannot be moved, so it adds exactly one pose, :func:`plate_view`),
which joins the board's poses; alone it cannot calibrate a plane.

Frames: world (the rig's), metres.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rangekit.boards import Board
from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError, InputError
from rangekit.geometry import apply_T, compose, invert_T, ray_plane_t
from rangekit.laser.plane_fit import PlaneFit, fit_plane
from rangekit.laser.triangulate import MIN_RAY_PLANE_ANGLE
from rangekit.rig.lasers import LineLaser

__all__ = ["TargetView", "board_view", "plate_view", "ViewUse", "LaserPlaneCalibration", "calibrate_laser_plane",
           "PlaneErrors", "plane_errors", "calibrated_laser", "report_lines"]


@dataclass(frozen=True, eq=False)
class TargetView:
    """One pose of a plane target lit by the laser.

    T_world_target : (4, 4) the target's pose; its plane is the frame's z = 0.
    points_uv : (N, 2) the laser line's subpixel points in the (distorted) camera image.
    name : names the pose in reports and errors ("board pose 3").
    extent : (x0, y0, x1, y1) metres, the target's rectangle in its frame (a board), or None.
    radius : metres, a disc about the frame's origin (the turntable plate), or None.
    """

    T_world_target: np.ndarray
    points_uv: np.ndarray
    name: str
    extent: tuple[float, float, float, float] | None = None
    radius: float | None = None

    def on_target(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: which (N, 2) target-frame points lie on the target."""
        ok = np.all(np.isfinite(xy), axis=1)
        if self.extent is not None:
            x0, y0, x1, y1 = self.extent
            ok &= (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
        if self.radius is not None:
            ok &= np.hypot(xy[:, 0], xy[:, 1]) <= self.radius
        return ok


def _uv(points_uv, name: str) -> np.ndarray:
    uv = np.asarray(points_uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise InputError(f"{name}: the laser points must be an (N, 2) array of (u, v) pixels, found shape "
                         f"{uv.shape}")
    return uv


def board_view(board: Board, points_uv, T_world_board=None, *, T_cam_board=None,
               camera: PinholeCamera | None = None, name: str = "board pose") -> TargetView:
    """A board pose: ``T_world_board``, or ``T_cam_board`` (camera calibration's board pose) with the
    ``camera`` whose pose it is relative to. The board's extent (margin included) bounds the points."""
    if (T_world_board is None) == (T_cam_board is None):
        raise InputError(f"{name}: give the board's pose as T_world_board or as T_cam_board with the camera, "
                         "exactly one")
    if T_cam_board is not None:
        if camera is None:
            raise InputError(f"{name}: T_cam_board needs the camera (its T_world_cam)")
        T_world_board = compose(camera.T_world_cam, np.asarray(T_cam_board, dtype=np.float64))
    return TargetView(np.asarray(T_world_board, dtype=np.float64), _uv(points_uv, name), name, extent=board.extent)


def plate_view(T_world_table, points_uv, radius: float = 0.15, name: str = "turntable plate") -> TargetView:
    """The bare turntable plate (its top is ``z = 0`` of ``T_world_table``, a disc of ``radius`` metres,
    0.15 m in the simulator) as one more target pose."""
    if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
        raise InputError(f"{name}: radius must be a finite number > 0 (metres), found {radius!r}")
    return TargetView(np.asarray(T_world_table, dtype=np.float64), _uv(points_uv, name), name, radius=float(radius))


@dataclass(frozen=True)
class ViewUse:
    """What one pose gave: ``n_points`` finite laser points, ``n_on_target`` of them on the target and on
    its straight line, ``n_inliers`` kept by the robust fit, ``reason`` why it was rejected ("" when used),
    ``n_off_line`` points on the target dropped as off the pose's straight line."""

    name: str
    n_points: int
    n_on_target: int
    n_inliers: int = 0
    reason: str = ""
    n_off_line: int = 0


@dataclass(frozen=True, eq=False)
class LaserPlaneCalibration:
    """One laser's calibrated plane.

    name : the laser's name.
    fit : the plane (world frame, normal towards the camera centre), RMS residual, inliers, spread.
    points : (M, 3) the 3D line points of the used poses, world frame (``fit.inliers`` indexes them).
    views : one :class:`ViewUse` per pose, in the order given.
    """

    name: str
    fit: PlaneFit
    points: np.ndarray
    views: tuple[ViewUse, ...]

    @property
    def plane(self) -> np.ndarray:
        return self.fit.plane

    @property
    def used(self) -> list[str]:
        return [v.name for v in self.views if not v.reason]

    @property
    def rejected(self) -> list[tuple[str, str]]:
        """(pose name, reason) of every rejected pose."""
        return [(v.name, v.reason) for v in self.views if v.reason]


def _target_points(camera: PinholeCamera, view: TargetView, min_angle: float,
                   line_tol_px: float | None) -> tuple[np.ndarray, int, int]:
    """(M, 3) world points of ``view``'s laser line on its target, the number of finite input points and the
    number of on-target points dropped off the line (:func:`_line_inliers`)."""
    uv = view.points_uv[np.all(np.isfinite(view.points_uv), axis=1)]
    if len(uv) == 0:
        return np.zeros((0, 3)), 0, 0
    T = view.T_world_target
    n = T[:3, 2]
    plane = np.append(n, -n @ T[:3, 3])
    o, d = camera.rays(uv)
    t = ray_plane_t(o, d, plane)
    with np.errstate(invalid="ignore"):
        ok = (np.abs(d @ n) >= math.sin(min_angle)) & (t > 0)
    X = o + t[:, None] * d
    X[~ok] = np.nan
    local = apply_T(invert_T(T), X)
    on = view.on_target(local[:, :2])
    X, xy = X[on], local[on, :2]
    if line_tol_px is None or len(X) < 3:
        return X, len(uv), 0
    # one pixel at the points' depth, in metres on the target (the line's tolerance)
    z = (apply_T(invert_T(camera.T_world_cam), X))[:, 2]
    px = float(np.median(z)) / float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))
    keep = _line_inliers(xy, line_tol_px * px)
    return X[keep], len(uv), int(len(X) - keep.sum())


def _line_inliers(xy: np.ndarray, tol: float, n_draws: int = 200, seed: int = 0) -> np.ndarray:
    """(N,) bool: the (N, 2) points within ``tol`` of the straight line most of them lie on.

    A laser plane meets a plane target in a straight line, so a pose's true line points are collinear on
    the target; peaks found elsewhere (noise in a row where the line is too faint, e.g. on a dark square)
    lie off it. Lines through ``n_draws`` random pairs are scored by their points within ``tol`` (one
    vectorised pass), the best is refitted to its inliers (SVD) and the points within ``tol`` kept."""
    rng = np.random.default_rng(seed)
    i, j = rng.integers(0, len(xy), (2, n_draws))
    ok = i != j
    i, j = i[ok], j[ok]
    if len(i) == 0:
        return np.ones(len(xy), bool)
    u = xy[j] - xy[i]
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-15)
    normal = np.column_stack([-u[:, 1], u[:, 0]])                              # (K, 2)
    dist = np.abs(np.einsum("knd,kd->kn", xy[None, :, :] - xy[i][:, None, :], normal))   # (K, N)
    best = int(np.argmax((dist <= tol).sum(axis=1)))
    keep = dist[best] <= tol
    for _ in range(2):
        c = xy[keep].mean(axis=0)
        _, _, Vt = np.linalg.svd(xy[keep] - c, full_matrices=False)
        keep = np.abs((xy - c) @ Vt[1]) <= tol
    return keep


def calibrate_laser_plane(camera: PinholeCamera, views: Sequence[TargetView], *, name: str = "laser",
                          min_points: int = 20, min_angle: float = MIN_RAY_PLANE_ANGLE,
                          line_tol_px: float | None = 1.0, seed: int = 0) -> LaserPlaneCalibration:
    """Fit laser ``name``'s plane from its lines on plane targets (module doc).

    Parameters
    ----------
    camera : the calibrated camera (its pose is the world frame's link to the targets).
    views : the target poses (:func:`board_view`, :func:`plate_view`), each with the laser line's points.
    min_points : a pose with fewer of its points on the target is rejected ("the line misses the board").
    min_angle : rays meeting the target's plane below this angle (radians) are dropped.
    line_tol_px : a pose's points further than this (pixels, converted to metres at the points' depth) from
        the straight line most of them lie on are dropped before the fit (false peaks where the line is too
        faint, e.g. on a dark square); None keeps them.

    Raises
    ------
    CalibrationError : no usable pose, or the used poses' lines lie on one line (the plane is undetermined);
        the message names the laser and the rejected poses with their reasons.
    """
    if not views:
        raise CalibrationError(f"laser {name!r}: no target poses given; a plane needs at least two poses whose "
                               "laser lines differ")
    uses, chunks, owners = [], [], []
    for i, view in enumerate(views):
        X, n_finite, n_off = _target_points(camera, view, min_angle, line_tol_px)
        if n_finite == 0:
            uses.append(ViewUse(view.name, 0, 0, reason="no laser points in the image"))
        elif len(X) < min_points:
            where = (f"board extent x {view.extent[0] * 1e3:.1f}..{view.extent[2] * 1e3:.1f} mm, y "
                     f"{view.extent[1] * 1e3:.1f}..{view.extent[3] * 1e3:.1f} mm" if view.extent is not None
                     else f"plate radius {view.radius * 1e3:.1f} mm" if view.radius is not None else "its plane")
            uses.append(ViewUse(view.name, n_finite, len(X), reason=(
                f"the laser line misses the target: {len(X)} of {n_finite} points fall on it ({where}), at "
                f"least {min_points} needed" + (f"; {n_off} more on it but off the line's straight line"
                                                 if n_off else ""))))
        else:
            uses.append(ViewUse(view.name, n_finite, len(X), n_off_line=n_off))
            chunks.append(X)
            owners.append(np.full(len(X), i))
    rejected = "; ".join(f"{u.name}: {u.reason}" for u in uses if u.reason)
    if not chunks:
        raise CalibrationError(f"laser {name!r}: no usable target pose (rejected: {rejected})")
    P = np.concatenate(chunks)
    owner = np.concatenate(owners)
    used_names = ", ".join(u.name for u in uses if not u.reason)
    what = f"laser {name!r}: the line points of {used_names}" + (f" (rejected: {rejected})" if rejected else "")
    _check_lines(chunks, what)
    fit = fit_plane(P, seed=seed, groups=owner, what=what)
    if fit.plane[:3] @ camera.center + fit.plane[3] < 0:
        fit = dataclasses.replace(fit, plane=-fit.plane)
    counts = np.bincount(owner[fit.inliers], minlength=len(views))
    uses = [dataclasses.replace(u, n_inliers=int(counts[i])) if not u.reason else u for i, u in enumerate(uses)]
    kept = [P[fit.inliers & (owner == i)] for i in range(len(views)) if counts[i] >= min_points]
    _check_lines(kept, what + " (inliers of the robust fit)")
    return LaserPlaneCalibration(name=name, fit=fit, points=P, views=tuple(uses))


def _check_lines(chunks: list[np.ndarray], what: str) -> None:
    """CalibrationError when the poses' lines lie on one 3D line (the plane may turn about it).

    Each pose's points are fitted to a line (centroid, direction, half-length from the spread, thickness
    sigma); the line's two ends of all poses must spread across, not only along, by more than ten times
    the thickest pose's sigma. Tested on the lines, not on the points: the noise of one pose lies in its
    target's plane, so the points of poses on one line are exactly coplanar with the target and a plane
    fit alone would return the target's plane."""
    ends, sigma = [], 0.0
    for X in chunks:
        c = X.mean(axis=0)
        _, s, Vt = np.linalg.svd(X - c, full_matrices=False)
        s = s / np.sqrt(len(X))
        half = math.sqrt(3.0) * s[0]
        ends += [c - half * Vt[0], c + half * Vt[0]]
        sigma = max(sigma, float(np.hypot(s[1], s[2])))
    E = np.asarray(ends)
    s = np.linalg.svd(E - E.mean(axis=0), compute_uv=False) / math.sqrt(len(E))
    if not s[1] > max(10.0 * sigma, 1e-6 * s[0]):
        raise CalibrationError(f"{what}: the laser lines of these poses are collinear (they lie on one 3D line: "
                               f"{s[1] * 1e3:.4f} mm across it, at least {10 * sigma * 1e3:.4f} mm needed), so the "
                               "plane may turn about that line and is not determined; add poses with the board "
                               "tilted or moved towards or away from the camera, so that the lines differ")


@dataclass(frozen=True)
class PlaneErrors:
    """A fitted plane against the true one: ``normal_angle`` (radians, between the normals, sign-free),
    ``offset`` (metres, |d_fit - d_true| with the normals aligned: the two planes' distances from the world
    origin), ``max_deviation`` (metres, the largest distance from the true plane of the fitted plane over
    the calibration points, projected onto it; NaN without points)."""

    normal_angle: float
    offset: float
    max_deviation: float


def plane_errors(plane, true_plane, points=None) -> PlaneErrors:
    """Compare two (4,) planes ``[n, d]`` (normalised here); ``points`` (N, 3) bound the region compared."""
    p = np.asarray(plane, dtype=np.float64)
    q = np.asarray(true_plane, dtype=np.float64)
    p, q = p / np.linalg.norm(p[:3]), q / np.linalg.norm(q[:3])
    if p[:3] @ q[:3] < 0:
        p = -p
    angle = float(np.arctan2(np.linalg.norm(np.cross(p[:3], q[:3])), p[:3] @ q[:3]))
    dev = float("nan")
    if points is not None:
        P = np.asarray(points, dtype=np.float64)
        P = P[np.all(np.isfinite(P), axis=1)]
        if len(P):
            on = P - (P @ p[:3] + p[3])[:, None] * p[:3]
            dev = float(np.max(np.abs(on @ q[:3] + q[3])))
    return PlaneErrors(normal_angle=angle, offset=float(abs(p[3] - q[3])), max_deviation=dev)


def calibrated_laser(laser: LineLaser, calibration: LaserPlaneCalibration) -> LineLaser:
    """``laser`` with the calibrated plane (every other field kept; an ``origin`` is projected onto the new
    plane so that it stays on it). The laser object that goes into the rig file."""
    plane = calibration.plane
    origin = laser.origin
    if origin is not None:
        origin = origin - (origin @ plane[:3] + plane[3]) * plane[:3]
    return dataclasses.replace(laser, plane=plane.copy(), origin=origin)


def report_lines(calibration: LaserPlaneCalibration, truth=None) -> list[str]:
    """Lines for ``rangekit calibrate --lasers``: the plane, its residual, the poses used and rejected, and
    with ``truth`` (a LineLaser or (4,) plane; the simulator's) the normal angle and offset errors."""
    f = calibration.fit
    n = f.plane
    lines = [f"laser {calibration.name!r}: plane n = [{n[0]:+.6f}, {n[1]:+.6f}, {n[2]:+.6f}], d = "
             f"{n[3] * 1e3:+.4f} mm; RMS residual {f.rms * 1e3:.4f} mm, {f.n_inliers}/{f.n_points} points from "
             f"{len(calibration.used)} poses"]
    for v in calibration.views:
        if v.reason:
            lines.append(f"  rejected {v.name}: {v.reason}")
        elif v.n_inliers < v.n_on_target / 2:
            lines.append(f"  {v.name}: {v.n_on_target - v.n_inliers} of {v.n_on_target} points off the plane "
                         "(outliers: check this pose's board pose)")
    if truth is not None:
        q = truth.plane if isinstance(truth, LineLaser) else truth
        e = plane_errors(n, q, calibration.points[f.inliers])
        lines.append(f"  against the truth: normal {math.degrees(e.normal_angle):.5f} deg, offset "
                     f"{e.offset * 1e3:.5f} mm (at most {e.max_deviation * 1e3:.5f} mm over the calibrated area)")
    return lines
