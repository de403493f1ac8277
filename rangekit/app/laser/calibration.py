"""Laser-plane calibration on the simulator: board poses rendered with each laser off and on, the board's
pose found from its corners (as camera calibration does), each laser's line triangulated on the board and
the lines of all poses fitted to its plane (:mod:`rangekit.laser.plane_calib`).

Per pose: the laser-off image gives the board's corners (:func:`rangekit.boards.detect_board`); the board
pose ``T_cam_board`` comes from camera calibration of the poses' corners (Zhang, :func:`calibrate_device`,
the camera then placed at the true rig's ``T_world_cam``), or, with a calibrated ``camera`` given (e.g. from
``rangekit calibrate``), from PnP with its intrinsics. Each laser frame's subpixel line peaks (laser on
minus off, :func:`rangekit.laser.detect_peaks`) are the line's points. Never the simulator's true pose.

Errors against the truth (:func:`rangekit.laser.plane_calib.plane_errors`: normal angle in degrees, offset
in mm = the difference of the planes' distances from the world origin, the turntable centre where objects
stand): the fitted plane in the calibrated rig's world frame against the true plane in the true world
frame. A rig calibrated by ``rangekit calibrate`` has its own world (the turntable frame, found by the same
camera), so a camera error that turns the whole camera frame (a principal point 0.3 px off: 0.01 deg,
0.09 mm at 0.5 m) turns the board poses, the laser planes and the turntable axis alike and cancels; the
``camera_errors`` (the fitted plane carried into the true world through the TRUE camera pose) keep it
and show how much of the error is the camera's. With the camera at the true pose the two agree.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import cv2
import numpy as np

from rangekit.boards import Board, detect_board
from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError, ConfigError, UsageError
from rangekit.geometry import compose, invert_T, make_T, rotvec_to_R
from rangekit.laser.peaks import detect_peaks
from rangekit.laser.plane_calib import (LaserPlaneCalibration, PlaneErrors, board_view, calibrate_laser_plane,
                                        calibrated_laser, plane_errors, report_lines)
from rangekit.laser.triangulate import MIN_RAY_PLANE_ANGLE
from rangekit.rig.lasers import LineLaser
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig

__all__ = ["LaserCalibration", "calibrate_lasers", "plane_in_world", "check_rays_cross_plane", "pose_lines",
           "pnp_board_poses", "fit_laser_planes"]


@dataclass(frozen=True, eq=False)
class LaserCalibration:
    """What :func:`calibrate_lasers` found.

    rig : the calibrated rig: the camera used and every laser's plane replaced by its fitted one (world frame
        of that camera); this goes into the rig file.
    lasers : per laser, its :class:`LaserPlaneCalibration` (plane fit, points, poses used and rejected).
    errors : per laser, the fitted plane in the calibrated rig's world frame against the true plane in the
        true world frame (:class:`PlaneErrors`; module doc), or None.
    camera_errors : the same relative to the camera (the fitted plane carried into the true world through
        the true camera pose; module doc).
    truth : the simulator's true rig (with its lasers).
    rejected : "laser0: board pose 3: reason" for every pose a laser did not use, and
        "board pose 3: reason" for a pose whose board was not found.
    camera_rms : px, the corners' reprojection RMS of the camera calibration (NaN when a camera was given).
    seconds : wall time of the whole calibration.
    """

    rig: Rig
    lasers: tuple[LaserPlaneCalibration, ...]
    errors: tuple[PlaneErrors, ...] | None
    camera_errors: tuple[PlaneErrors, ...] | None
    truth: Rig | None
    rejected: tuple[str, ...]
    camera_rms: float
    seconds: float

    def worst(self) -> tuple[float, float]:
        """(degrees, mm): the largest normal angle error and offset error over the lasers (NaN without truth)."""
        if not self.errors:
            return math.nan, math.nan
        return (max(math.degrees(e.normal_angle) for e in self.errors), max(e.offset * 1e3 for e in self.errors))

    def summary_lines(self) -> list[str]:
        """Lines for ``rangekit calibrate --lasers``: per laser its plane, residual, poses used and rejected
        (by name), and on the simulator its normal angle and offset errors against the truth."""
        lines = []
        if not math.isnan(self.camera_rms):
            lines.append(f"camera (from the board poses): reprojection RMS {self.camera_rms:.4f} px")
        lines += [f"rejected {r}" for r in self.rejected if r.startswith("board pose")]
        for k, cal in enumerate(self.lasers):
            lines += report_lines(cal)
            if self.errors is not None:
                e = self.errors[k]
                c = self.camera_errors[k]
                lines.append(f"  against the truth: normal angle error {math.degrees(e.normal_angle):.5f} deg, "
                             f"offset error {e.offset * 1e3:.5f} mm (world frame; relative to the camera "
                             f"{math.degrees(c.normal_angle):.5f} deg, {c.offset * 1e3:.5f} mm)")
        lines.append(f"laser calibration: {self.seconds:.1f} s")
        return lines


def plane_in_world(plane, T_world_from: np.ndarray, T_world_to: np.ndarray) -> np.ndarray:
    """(4,) ``plane`` given in a world where the camera is at ``T_world_from``, expressed in the world where
    the same camera is at ``T_world_to`` (both (4, 4) ``T_world_cam``)."""
    T = compose(np.asarray(T_world_to, dtype=np.float64), invert_T(np.asarray(T_world_from, dtype=np.float64)))
    p = np.asarray(plane, dtype=np.float64)
    n = T[:3, :3] @ p[:3]
    return np.append(n, p[3] - n @ T[:3, 3])


def check_rays_cross_plane(cal: LaserPlaneCalibration, camera: PinholeCamera,
                           min_angle: float = MIN_RAY_PLANE_ANGLE) -> None:
    """CalibrationError naming the laser when the camera's rays to its calibrated points meet the fitted
    plane at a median angle below ``min_angle`` radians (the plane nearly holds the camera centre): such a
    laser cannot triangulate anything, however well its plane is known."""
    P = cal.points[cal.fit.inliers]
    d = P - camera.center
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    angle = float(np.median(np.arcsin(np.clip(np.abs(d @ cal.plane[:3]), 0, 1))))
    if not angle >= min_angle:
        dist = abs(float(cal.plane[:3] @ camera.center + cal.plane[3]))
        raise CalibrationError(
            f"laser {cal.name!r}: its calibrated plane passes {dist * 1e3:.2f} mm from camera {camera.name!r}'s "
            f"centre, so the camera's rays meet it at {math.degrees(angle):.3f} deg (median; at least "
            f"{math.degrees(min_angle):g} deg needed): nearly parallel to the rays, it cannot triangulate; move "
            "the laser away from the camera (Ciclop: about 30 deg to either side of it)")


def pose_lines(off: np.ndarray, frames: Sequence[np.ndarray], board: Board, lasers: Sequence[LineLaser]):
    """One board pose's corners and laser lines: ``(detection, [uv (N, 2) per laser])``, or the reason
    (a string) when the board is not found in the laser-off image ``off``. ``frames``: one laser-on image
    per laser, (H, W) or (H, W, 3) like ``off`` (colour: each laser's ``channel`` is used)."""
    det = detect_board(off, board)
    if not det.found:
        return f"board not found in the laser-off image ({det.reason})"
    colour = np.ndim(off) == 3
    return det, [detect_peaks(f, off, channel=laser.channel if colour else None).points
                 for f, laser in zip(frames, lasers)]


def pnp_board_poses(camera: PinholeCamera, board: Board, views: Sequence, names: Sequence[str]):
    """``({pose index: T_cam_board (4, 4)}, [rejection])``: each found pose of ``views`` (from
    :func:`pose_lines`; None: not found) by PnP with the calibrated ``camera``; a PnP failure is rejected
    by the pose's name."""
    obj = board.object_points()
    T_cam, rejected = {}, []
    for i, v in enumerate(views):
        if v is None:
            continue
        ok, rvec, tvec = cv2.solvePnP(obj[v[0].ids], v[0].uv, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if ok:
            T_cam[i] = make_T(rotvec_to_R(rvec.ravel()), tvec.ravel())
        else:
            rejected.append(f"{names[i]}: the board's pose was not found from its corners (solvePnP failed)")
    return T_cam, rejected


def fit_laser_planes(lasers: Sequence[LineLaser], camera: PinholeCamera, board: Board, views: Sequence,
                     T_cam: dict, names: Sequence[str], *, min_points: int = 20, seed: int = 0):
    """``(calibrated lasers, [LaserPlaneCalibration], [rejection])``: each laser's line on the board poses
    ``T_cam`` (from :func:`pnp_board_poses`) fitted to its plane (world frame of ``camera``); rejections
    read "laser0: board pose 3: reason". Raises CalibrationError (named) as :func:`calibrate_laser_plane`
    and :func:`check_rays_cross_plane` do."""
    out, cals, rejected = [], [], []
    for k, laser in enumerate(lasers):
        targets = [board_view(board, views[i][1][k], T_cam_board=T_cam[i], camera=camera, name=names[i])
                   for i in sorted(T_cam) if i < len(views)]
        cal = calibrate_laser_plane(camera, targets, name=laser.name, min_points=min_points, seed=seed)
        check_rays_cross_plane(cal, camera)
        rejected += [f"{laser.name}: {n}: {why}" for n, why in cal.rejected]
        cals.append(cal)
        out.append(calibrated_laser(laser, cal))
    return out, cals, rejected


def calibrate_lasers(truth: Rig | None = None, *, n_poses: int = 10, seed: int = 0, board: Board | None = None,
                     camera: PinholeCamera | None = None, poses: Sequence[np.ndarray] | None = None,
                     camera_poses: int = 10, ambient_scale: int = 2, min_points: int = 20,
                     progress: Callable | None = None) -> LaserCalibration:
    """Calibrate every laser plane of the simulated rig ``truth`` from ``n_poses`` rendered board poses.

    Parameters
    ----------
    truth : the simulator's true rig with lasers (default :func:`rangekit.sim.laser.rig.laser_rig`).
    n_poses : board poses (:func:`rangekit.sim.laser.board.laser_board_poses`, seeded by ``seed``).
    seed : poses and sensor noise.
    board : the calibration board (default ``Board()``: 10 x 7 squares of 20 mm).
    camera : a calibrated camera (intrinsics and ``T_world_cam`` of the calibrated rig) to find the board
        poses by PnP; default: calibrated here (Zhang) from the corners of the laser poses and of
        ``camera_poses`` more board poses spread over the image (:func:`rangekit.sim.writers.calibration.board_poses`,
        laser-off image only), placed at the true camera pose.
    poses : explicit true ``T_world_board`` poses instead of drawn ones (tests: a pose missing a line).
    camera_poses : the extra camera-calibration poses (without ``camera``); 0: the laser poses alone.
    ambient_scale : :class:`rangekit.sim.laser.frames.LaserView`'s: 2 renders the board's texture at half resolution
        (0.044 px RMS corner error instead of 0.026 px, 3.5x faster), 1 at full resolution.
    min_points : line points on the board below which a pose is rejected for that laser.

    Returns
    -------
    :class:`LaserCalibration` (its ``rig`` goes into the rig file).

    Raises
    ------
    CalibrationError : the board is found in too few poses; a laser lights no pose (named); the lines of a
        laser's poses are collinear; a plane nearly parallel to the camera rays (named).
    """
    from rangekit.calib.camera import Correspondences, calibrate_device
    from rangekit.sim.writers.calibration import board_poses
    from rangekit.sim.laser.board import laser_board_poses, render_board_pose
    from rangekit.sim.laser.rig import laser_rig

    t0 = time.perf_counter()
    if not isinstance(n_poses, int) or n_poses < 2:
        raise UsageError(f"laser calibration: the number of board poses must be at least 2, found {n_poses!r}")
    truth = truth if truth is not None else laser_rig()
    if not truth.lasers:
        raise ConfigError("laser calibration: the rig has no lasers (rig file 'lasers': none); use "
                          "rangekit.sim.laser.rig.laser_rig()")
    board = board if board is not None else Board()
    poses = list(poses) if poses is not None else laser_board_poses(truth, board, n_poses, seed=seed)
    names = [f"board pose {i + 1}" for i in range(len(poses))]
    obj = board.object_points()
    rejected: list[str] = []
    views = []
    for i, T in enumerate(poses):
        call_progress(progress, "laser calibration: rendering board poses", i, len(poses))
        shot = render_board_pose(truth, board, T, seed=seed * 1000 + i, ambient_scale=ambient_scale)
        view = pose_lines(shot.off, shot.frames, board, truth.lasers)
        if isinstance(view, str):
            rejected.append(f"{names[i]}: {view}")
            view = None
        views.append(view)
    call_progress(progress, "laser calibration: rendering board poses", len(poses), len(poses))
    camera_rms = math.nan
    if camera is None:
        corr = [Correspondences(v[0].ids, v[0].uv) if v is not None else None for v in views]
        extra = board_poses(truth, board, camera_poses, seed=seed) if camera_poses > 0 else []
        for j, T in enumerate(extra):
            call_progress(progress, "laser calibration: camera poses", j, len(extra))
            det = detect_board(render_board_pose(truth, board, T, seed=seed * 1000 + 500 + j,
                                                 ambient_scale=ambient_scale, lasers=False).off, board)
            corr.append(Correspondences(det.ids, det.uv, det.reason) if det.found else None)
        dev = calibrate_device(corr, obj, (truth.camera.width, truth.camera.height), name=truth.camera.name,
                               names=names + [f"camera pose {j + 1}" for j in range(len(extra))])
        camera = dataclasses.replace(dev.device, T_world_cam=truth.camera.T_world_cam.copy())
        camera_rms = dev.rms
        T_cam = dev.T_dev_board
        rejected += [f"{v.name}: {v.reason}" for v in dev.views
                     if not v.used and (v.index >= len(views) or views[v.index] is not None)]
    else:
        T_cam, failed = pnp_board_poses(camera, board, views, names)
        rejected += failed
    lasers, cals, fit_rejected = fit_laser_planes(truth.lasers, camera, board, views, T_cam, names,
                                                  min_points=min_points, seed=seed)
    rejected += fit_rejected
    errors, camera_errors = [], []
    for cal, laser in zip(cals, truth.lasers):
        inliers = cal.points[cal.fit.inliers]
        errors.append(plane_errors(cal.plane, laser.plane, inliers))
        in_truth = plane_in_world(cal.plane, camera.T_world_cam, truth.camera.T_world_cam)
        camera_errors.append(plane_errors(in_truth, laser.plane))
    rig = dataclasses.replace(truth, cameras=(camera,) + tuple(truth.cameras[1:]), lasers=tuple(lasers))
    return LaserCalibration(rig=rig, lasers=tuple(cals), errors=tuple(errors), camera_errors=tuple(camera_errors),
                            truth=truth,
                            rejected=tuple(rejected), camera_rms=camera_rms, seconds=time.perf_counter() - t0)
