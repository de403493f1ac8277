"""``rangekit calibrate --lasers --captures DIR [DIR ...] --pattern laser:...``: a laser rig (one camera, line lasers,
a turntable; Ciclop/Horus/FabScan style) calibrated from recorded board sweeps, with no projector and no device.

Each DIR is a laser recording (:mod:`rangekit.formats.layouts.laser`) of the calibration board standing on the
turntable, turned step by step, with the laser-off frame (or, without it, the darkest of the step's laser frames)
and one frame per laser at each step: the boards' images without the laser line give the corners, those with it
the lines across the board. From them (Horus's order: camera, laser planes, platform):

1. **the camera**: Zhang's calibration (:func:`rangekit.calib.camera.calibrate_device`) from the corners of every
   step of every sweep; the board's pose at each step comes with it;
2. **the turntable axis**: per sweep, the board's poses at its step angles fitted to rotations about one axis
   (:func:`rangekit.calib.turntable.fit_turntable_axis`: the corners' reprojection error over the axis, the angle
   scale and the reference pose); the sweeps' axes are averaged, weighted by their steps, and their spread said;
3. **the laser planes**: each laser's line points on each board pose (laser on minus laser off, Gaussian peaks),
   met with that pose's board plane and fitted to one plane over all poses
   (:func:`rangekit.app.laser.calibration.fit_laser_planes`: robust, poses whose line misses the board named);
4. **the table top**: the laser points of every step met with their planes; the densest height along the axis is
   the turntable's top, where the lines cross the disc beside the board
   (:func:`rangekit.calib.turntable.turntable_frame`), unless it lies above the board's lowest edge (which stands
   on the table): then that edge.

The rig file's world is the turntable frame (z up the axis, origin on it at the table top, y from the camera
towards the axis), as the simulator's and ``rangekit calibrate``'s.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.boards import Board
from rangekit.errors import CalibrationError, FileFormatError, UsageError
from rangekit.geometry import invert_T
from rangekit.rig.lasers import LineLaser
from rangekit.rig.rig_file import Rig

__all__ = ["RecordedLaserCalibration", "calibrate_laser_recordings", "ambient_frame", "TABLE_BELOW_BOARD"]

#: The densest height of the laser points is taken for the table top only if it lies at most this far (m) above
#: the board's lowest edge, which stands on the table (else it is the board's own, and that edge is taken).
TABLE_BELOW_BOARD = 0.005


def ambient_frame(off: np.ndarray | None, frames: Sequence[np.ndarray]) -> np.ndarray:
    """The laser-off image of a step: ``off`` when recorded; else the per-pixel minimum of its laser frames (each
    laser's line is dark in the others' frames), or zeros with a single laser (the line over the room light)."""
    if off is not None:
        return off
    if len(frames) >= 2:
        return np.minimum.reduce([np.asarray(f) for f in frames])
    return np.zeros_like(frames[0])


@dataclass(frozen=True, eq=False)
class RecordedLaserCalibration:
    """What :func:`calibrate_laser_recordings` found: the ``rig`` written; the camera's reprojection RMS (px); the
    fitted ``axis`` (:class:`rangekit.calib.turntable.AxisFit`, camera frame) and each sweep's; the table top's
    height along the axis (m from the axis point nearest the camera), from the lines on the table or else from the
    board's lowest edge (``table_from_lines``); each laser's
    :class:`rangekit.laser.plane_calib.LaserPlaneCalibration`; every rejection by name; the figures against the
    simulator's truth (``truth_lines``) when the recordings carry it."""

    rig: Rig
    camera_rms: float
    axis: object
    sweep_axes: tuple
    table_height: float
    table_from_lines: bool
    lasers: tuple
    rejected: tuple[str, ...]
    truth_lines: tuple[str, ...]
    axis_error_deg: float | None
    seconds: float

    def summary_lines(self) -> list[str]:
        from rangekit.laser.plane_calib import report_lines

        cam = self.rig.camera
        K = cam.K
        lines = [f"camera: reprojection RMS {self.camera_rms:.4f} px; fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx "
                 f"{K[0, 2]:.2f} cy {K[1, 2]:.2f}"]
        lines += self.axis.summary_lines()
        if len(self.sweep_axes) > 1:
            spread = max(math.degrees(math.acos(min(1.0, abs(float(a.direction @ self.axis.direction)))))
                         for a in self.sweep_axes)
            lines.append(f"  {len(self.sweep_axes)} sweeps' axes within {spread:.4f} deg of their mean")
        lines.append(f"table top: {self.table_height * 1e3:+.3f} mm along the axis from its point nearest the camera, "
                     + ("where the laser lines cross it" if self.table_from_lines else
                        "the board's lowest edge (too few laser points on the table itself)"))
        lines += [f"rejected {r}" for r in self.rejected]
        lines.append("laser planes (camera frame; the rig file holds them in the turntable frame):")
        for cal in self.lasers:
            lines += report_lines(cal)
        lines += list(self.truth_lines)
        lines.append(f"laser rig calibration: {self.seconds:.1f} s")
        return lines


def _read_sweeps(captures, layout, step_deg, board, report):
    """Every step of every recording read: (names, views (pose_lines results or None), corners, angles per sweep,
    indices per sweep, size, n_lasers, rejected)."""
    from rangekit.app.laser.calibration import pose_lines
    from rangekit.calib.camera import Correspondences
    from rangekit.formats.layouts.laser import read_laser_recording, read_step_frames

    names, views, corr, sweeps, rejected, size, n_lasers = [], [], [], [], [], None, None
    for folder in captures:
        rec = read_laser_recording(folder, layout, step_deg=step_deg)
        if report is not None:
            report(rec.line())
        if n_lasers is None:
            n_lasers = rec.n_lasers
        elif rec.n_lasers != n_lasers:
            raise FileFormatError(f"{folder}: {rec.n_lasers} laser(s) a step, {captures[0]} {n_lasers}; every "
                                  "recording must come from the same rig")
        lasers = [LineLaser(plane=np.array([1.0, 0, 0, 1.0]), name=f"laser{k}") for k in range(n_lasers)]
        members = []
        for step in rec.steps:
            off, frames = read_step_frames(step)
            ambient = ambient_frame(off, frames)
            shape = (ambient.shape[1], ambient.shape[0])
            if size is None:
                size = shape
            elif shape != size:
                raise FileFormatError(f"{step.lasers[0]}: images are {shape[0]}x{shape[1]}, those of {captures[0]} "
                                      f"{size[0]}x{size[1]}; every recording must come from the same camera")
            name = f"{Path(folder).name} step {step.index}"
            view = pose_lines(ambient, frames, board, lasers)
            if isinstance(view, str):
                rejected.append(f"{name}: {view} ({step.off or step.lasers[0]})")
                view = None
            members.append((len(names), step.angle))
            names.append(name)
            views.append(view)
            corr.append(Correspondences(view[0].ids, view[0].uv) if view is not None else None)
        sweeps.append(members)
    return names, views, corr, sweeps, size, n_lasers, rejected, lasers


def _fit_axis(camera, board: Board, views, sweeps, T_cam: dict, names, rejected: list):
    """The mean axis of the sweeps that fix one (>= 3 poses over >= 20 deg), and each sweep's."""
    from rangekit.calib.turntable import AxisFit, fit_turntable_axis

    obj = board.object_points()
    fits = []
    for members in sweeps:
        used = [(i, a) for i, a in members if i in T_cam]
        if len(used) < 3 or np.ptp([a for _, a in used]) < math.radians(20):
            rejected.append(f"{names[members[0][0]].rsplit(' step', 1)[0]}: no turntable axis from it: the board found "
                            f"at {len(used)} steps over {math.degrees(np.ptp([a for _, a in used] or [0])):.1f} deg "
                            "(at least 3 steps over 20 deg needed)")
            continue
        fits.append(fit_turntable_axis(camera, obj, [a for _, a in used],
                                       [(views[i][0].ids, views[i][0].uv) for i, _ in used],
                                       [T_cam[i] for i, _ in used]))
    if not fits:
        raise CalibrationError("turntable axis: no recording holds the board at 3 or more steps over at least 20 deg; "
                               "record the board standing on the turntable, turned over 40-60 deg in steps")
    w = np.array([len(f.angles) for f in fits], dtype=np.float64)
    ref = fits[int(np.argmax(w))].direction
    dirs = np.array([f.direction if f.direction @ ref > 0 else -f.direction for f in fits])
    a = (w[:, None] * dirs).sum(axis=0)
    a /= np.linalg.norm(a)
    # each sweep's axis point nearest the camera centre, moved onto the mean direction's line
    pts = np.array([f.point - (f.point @ a) * a for f in fits])
    p = (w[:, None] * pts).sum(axis=0) / w.sum()
    rms = float(np.sqrt((w * np.array([f.rms for f in fits]) ** 2).sum() / w.sum()))
    scale = float((w * np.array([f.angle_scale for f in fits])).sum() / w.sum())
    mean = AxisFit(direction=a, point=p, angle_scale=scale, rms=rms,
                   view_rms=tuple(r for f in fits for r in f.view_rms), angles=tuple(t for f in fits for t in f.angles))
    return mean, tuple(fits)


def _table_points(camera, planes, views) -> np.ndarray | None:
    """Every step's laser points met with their laser's fitted plane (camera frame): the table top is among them."""
    from rangekit.laser.triangulate import triangulate_peaks

    chunks = []
    for v in views:
        if v is None:
            continue
        for k, uv in enumerate(v[1]):
            tri = triangulate_peaks(uv, camera, planes[k])
            chunks.append(tri.points)
    return np.concatenate(chunks) if chunks else None


def _board_bottom(axis, board: Board, T_cam: dict) -> float:
    """The lowest height along the axis of the board's outline over its poses (m from ``axis.point``): the board
    stands on the table, so its bottom edge is the table top when its lines on the table are too few."""
    x0, y0, x1, y1 = board.extent
    outline = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x0, y1, 0.0], [x1, y1, 0.0]])
    return float(min(float(np.min(((T[:3, :3] @ outline.T).T + T[:3, 3] - axis.point) @ axis.direction))
                     for T in T_cam.values()))


def _refined_height(axis, P: np.ndarray, height: float) -> float:
    """The table top's height along the axis, the median of the points within 0.3 then 0.1 mm of ``height``
    (:func:`rangekit.calib.turntable.turntable_frame`'s median over 1 mm takes in the board's bottom edge)."""
    h = (P[np.all(np.isfinite(P), axis=1)] - axis.point) @ axis.direction
    for window in (3e-4, 1e-4):
        near = np.abs(h - height) < window
        if near.sum() < 50:
            break
        height = float(np.median(h[near]))
    return height


def calibrate_laser_recordings(out: str | Path, captures: Sequence[str | Path], *, layout: str, board: Board,
                               step_deg: float | None = None, lens: str = "k1k2p", force: bool = False,
                               report: Callable[[str], object] | None = None) -> RecordedLaserCalibration:
    """Calibrate a laser rig from recorded board sweeps (module doc) and write the rig file ``out``.

    Raises
    ------
    UsageError : ``out`` exists (without ``force``), no capture, a capture that is not a folder, an unknown layout.
    FileFormatError : a recording without frames, a frame missing, a bad step table (named), images of two sizes.
    CalibrationError : too few board poses, no sweep fixing the axis, a laser lighting no pose (each named).
    """
    from rangekit.app.laser.calibration import fit_laser_planes, plane_in_world
    from rangekit.calib.camera import LENS_MODELS, calibrate_device
    from rangekit.calib.turntable import turntable_frame
    from rangekit.laser.plane_calib import calibrated_laser
    from rangekit.rig.rig_file import save_rig

    t0 = time.perf_counter()
    out = Path(out)
    if out.exists() and not force:
        raise UsageError(f"--out {out}: exists; choose another file or pass --force to overwrite it")
    if not captures:
        raise UsageError("--captures: give the folders of the recorded board sweeps")
    if lens not in LENS_MODELS:
        raise UsageError(f"--lens {lens}: expected one of {', '.join(LENS_MODELS)}")
    for c in captures:
        if not Path(c).is_dir():
            raise UsageError(f"--captures {c}: expected a folder of laser frames ({layout}), found "
                             f"{'a file' if Path(c).exists() else 'nothing'}")
    names, views, corr, sweeps, size, n_lasers, rejected, lasers = _read_sweeps(list(captures), layout, step_deg,
                                                                                 board, report)
    dev = calibrate_device(corr, board.object_points(), size, name="camera", names=names,
                           flags=LENS_MODELS[lens].camera_flags)
    camera = dev.device                                  # world = the camera's frame for now
    T_cam = dev.T_dev_board
    rejected += [f"{v.name}: {v.reason}" for v in dev.views if not v.used and views[v.index] is not None]
    axis, fits = _fit_axis(camera, board, views, sweeps, T_cam, names, rejected)
    fitted, cals, fit_rejected = fit_laser_planes(lasers, camera, board, views, T_cam, names)
    rejected += fit_rejected
    table = _table_points(camera, [c.plane for c in cals], views)
    T_cam_table, _ = turntable_frame(axis, None)
    bottom = _board_bottom(axis, board, T_cam)     # the board stands on the table: its lowest edge is on it
    try:
        height = _refined_height(axis, table, turntable_frame(axis, table)[1])
        from_table = height <= bottom + TABLE_BELOW_BOARD
    except CalibrationError:        # too few points for a table top
        from_table = False
    if not from_table:
        height = bottom
    T_cam_table[:3, 3] = axis.point + height * axis.direction
    T_world_cam = invert_T(T_cam_table)
    world_lasers = tuple(dataclasses.replace(calibrated_laser(laser, c), origin=None, switch=k + 1,
                                             plane=plane_in_world(c.plane, np.eye(4), T_world_cam))
                         for k, (laser, c) in enumerate(zip(fitted, cals)))
    rig = Rig(cameras=(dataclasses.replace(camera, T_world_cam=T_world_cam),), T_world_table=np.eye(4),
              lasers=world_lasers)
    truth_lines, axis_err = _against_truth(captures, rig, axis, cals)
    save_rig(rig, out)
    return RecordedLaserCalibration(rig, float(dev.rms), axis, fits, height, from_table, tuple(cals), tuple(rejected),
                                    tuple(truth_lines), axis_err, time.perf_counter() - t0)


def _against_truth(captures, rig: Rig, axis, cals) -> tuple[list[str], float | None]:
    """Lines comparing the calibration with the simulator's truth beside the recordings (none for a real one): the
    axis direction in the camera frame, each plane relative to the camera, the intrinsics."""
    from rangekit.app.laser.calibration import plane_in_world
    from rangekit.laser.plane_calib import plane_errors
    from rangekit.sim.laser.recording import recording_truth

    truth = recording_truth(captures[0])
    if truth is None or truth.rig.T_world_table is None:
        return [], None
    true_cam = truth.rig.camera
    T_cam_world = invert_T(true_cam.T_world_cam)
    true_axis = T_cam_world[:3, :3] @ truth.rig.T_world_table[:3, 2]
    err = math.degrees(math.acos(min(1.0, abs(float(true_axis @ axis.direction)))))
    foot = T_cam_world[:3, :3] @ truth.rig.T_world_table[:3, 3] + T_cam_world[:3, 3]
    d = axis.point - foot
    off = float(np.linalg.norm(d - (d @ true_axis) * true_axis))
    K, Kt = rig.camera.K, true_cam.K
    lines = [f"against the truth: turntable axis {err:.4f} deg off, passing {off * 1e3:.3f} mm from the true one; "
             f"fx {K[0, 0] - Kt[0, 0]:+.2f} fy {K[1, 1] - Kt[1, 1]:+.2f} cx {K[0, 2] - Kt[0, 2]:+.2f} cy "
             f"{K[1, 2] - Kt[1, 2]:+.2f} px"]
    for cal, laser in zip(cals, truth.rig.lasers):
        true_plane = plane_in_world(laser.plane, true_cam.T_world_cam, np.eye(4))   # into the true camera frame
        e = plane_errors(cal.plane, true_plane)
        lines.append(f"  laser {cal.name!r} against the truth (camera frame): normal {math.degrees(e.normal_angle):.4f} "
                     f"deg, offset {e.offset * 1e3:.4f} mm")
    return lines, err
