"""The whole rig calibration: projector response, camera, projector, their extrinsics, turntable axis.

:func:`calibrate_rig` drives the devices (simulated or real, through :mod:`rangekit.rig.devices`):

1. projector response: uniform grey levels on the board at its first pose (:mod:`rangekit.calib.response`);
2. for each board pose (``place_board(i, n)`` puts it there: the simulator moves it, on hardware the user
   does and confirms): a coded-light sequence (default ``hybrid``; its white frame finds the corners);
3. camera calibration from the corners (:func:`rangekit.calib.camera.calibrate_device`);
4. projector coordinates of each corner from the decoded maps
   (:func:`rangekit.calib.projector.corner_projector_coords`), projector calibration as an inverse camera, then
   a bundle adjustment of both devices and every board pose (:func:`rangekit.calib.pair.calibrate_pair`, shared
   with calibration from recorded sequences);
5. turntable (when there is one): the board fixed on the table (``place_on_turntable()``), a sequence at
   each angle; board poses by PnP, the axis fit (:mod:`rangekit.calib.turntable`), the table top from the
   triangulated scene at the middle angle.

The result is a :class:`rangekit.rig.rig_file.Rig` whose world is the turntable frame (z up the axis, origin on the
axis at the table top, y horizontal from the camera to the axis), the simulator's convention, or the
camera frame when there is no turntable. :func:`compare_rigs` gives each parameter's deviation from a
reference rig (the simulator's truth).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import cv2
import numpy as np

from rangekit.boards import Board, detect_board
from rangekit.calib.camera import LENS_MODELS, Correspondences, DeviceCalibration
from rangekit.calib.pair import calibrate_pair
from rangekit.calib.pose_feedback import FeedbackLimits, PoseCheck, check_pose, coverage_image
from rangekit.calib.projector import BundleResult, corner_projector_coords
from rangekit.calib.response import measure_response
from rangekit.calib.turntable import AxisFit, fit_turntable_axis, turntable_frame
from rangekit.camera import PinholeCamera
from rangekit.coded.decode import decode
from rangekit.errors import CalibrationError
from rangekit.geometry import compose, invert_T, make_T, rotation_angle, rotvec_to_R
from rangekit.coded.patterns import make_pattern_spec
from rangekit.progress import call_progress
from rangekit.coded.response import ResponseFit
from rangekit.rig.rig_file import Rig
from rangekit.coded.triangulate import triangulate

__all__ = ["CalibrationSettings", "RigCalibration", "calibrate_rig", "compare_rigs"]


@dataclass(frozen=True)
class CalibrationSettings:
    """What :func:`calibrate_rig` captures. Angles in degrees (typed by people)."""

    board: Board = field(default_factory=Board)
    n_poses: int = 20                      # hand-held board poses for camera and projector
    patterns: str = "hybrid"               # coded light for the projector coordinates of the corners
    turntable_angles_deg: tuple[float, ...] = (-40.0, -30.0, -20.0, -10.0, 0.0, 10.0, 20.0, 30.0, 40.0)
    response_levels: int = 17              # grey levels for the projector response (0 and 1 included)
    corner_radius: int = 8                 # half-window (camera px) of the corner's local fit
    measure_response: bool = True
    feedback: FeedbackLimits = field(default_factory=FeedbackLimits)   # when a board pose is rejected
    max_attempts: int = 10                 # captures of one pose at most (retakes asked for by ``on_pose``)
    lens: str = "k1k2p"                    # what each device fits: a name of rangekit.calib.camera.LENS_MODELS

    def __post_init__(self) -> None:
        if self.lens not in LENS_MODELS:
            raise CalibrationError(f"CalibrationSettings: lens must be one of {', '.join(LENS_MODELS)}, found "
                                   f"{self.lens!r}")


@dataclass(frozen=True, eq=False)
class RigCalibration:
    """Everything :func:`calibrate_rig` found; ``rig`` is what goes into the rig file."""

    rig: Rig
    camera: DeviceCalibration
    projector: DeviceCalibration
    bundle: BundleResult
    axis: AxisFit | None
    response: ResponseFit | None
    corner_std_projector: float            # median standard error of a corner's projector coordinates, px
    seconds: dict
    pose_checks: tuple[PoseCheck, ...] = ()    # the verdict on each board pose (the last capture of it)
    retaken: int = 0                           # captures retaken after a rejection
    lens: str = "k1k2p"                        # the lens model fitted (rangekit.calib.camera.LENS_MODELS)
    pose_names: tuple[str, ...] = ()           # each pose's name in the lines ("pose 1", ... when empty)

    def pose_check_line(self, check: PoseCheck) -> str:
        """``check.line()`` with the pose's name (:attr:`pose_names`) for "pose N"."""
        line = check.line()
        return f"{self.pose_names[check.index]}: {line.split(': ', 1)[1]}" if self.pose_names else line

    def pose_table(self) -> list[str]:
        """One line per board pose: its name, corners used by each device and the reprojection RMS of each
        at the bundle adjustment (px), or why it was not used."""
        lines = [f"  {'pose':<14} {'corners':>7} {'camera px':>10} {'projector px':>13}"]
        for cam, proj in zip(self.camera.views, self.projector.views):
            rms = self.bundle.view_rms.get(cam.index)
            if rms is None:
                lines.append(f"  {cam.name:<14} not used: {cam.reason or proj.reason or 'not in the bundle'}")
            else:
                lines.append(f"  {cam.name:<14} {cam.n_corners:>3}/{proj.n_corners:<3} {rms[0]:>10.4f} {rms[1]:>13.4f}")
        return lines

    def summary_lines(self) -> list[str]:
        b = self.bundle
        base = np.linalg.norm(b.T_cam_proj[:3, 3])
        T_proj_cam = invert_T(b.T_cam_proj)
        checks = self.pose_checks
        kept = sum(c.accepted for c in checks)
        lines = [f"board poses: {kept} of {len(checks)} kept ({len(checks) - kept} skipped, {self.retaken} retaken)"]
        lines += [f"  {self.pose_check_line(c)}" for c in checks if not c.accepted]
        lines += [f"camera: {len(self.camera.used)}/{len(self.camera.views)} board poses used; "
                 f"reprojection RMS {b.rms_camera:.4f} px (bundle adjusted; {self.camera.rms:.4f} px alone)",
                 f"projector: reprojection RMS {b.rms_projector:.4f} px (bundle adjusted; {self.projector.rms:.4f} "
                 f"px alone); corner coordinates +- {self.corner_std_projector:.4f} px (median standard error)",
                 f"camera-projector baseline {base * 1e3:.3f} mm; the camera's points in the projector's frame "
                 f"X_proj = R X_cam + T, T = ({', '.join(f'{x * 1e3:.2f}' for x in T_proj_cam[:3, 3])}) mm",
                 f"lens model: {self.lens} ({LENS_MODELS[self.lens].description})"]
        for dev in (b.camera, b.projector):
            K = dev.K
            lines.append(f"  {dev.name}: fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f} "
                         f"dist {' '.join(f'{x:.5f}' for x in dev.dist)}")
        lines += ["per board pose, bundle adjusted (corners: camera/projector):"] + self.pose_table()
        if self.response is not None:
            lines.append(f"projector response: gamma {self.response.response.gamma:.4f}")
        if self.axis is not None:
            lines += self.axis.summary_lines()
        rejected = [v.line() for v in self.camera.views if not v.used]
        lines += [f"  {r}" for r in rejected]
        lines.append("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()))
        return lines


def _capture(devices, frames: Sequence[np.ndarray], delay_s: float = 0.0) -> list[np.ndarray]:
    """Show each frame and capture it, waiting ``delay_s`` for the display (the simulator renders the whole
    sequence at once)."""
    fast = getattr(devices, "capture_sequence", None)
    if fast is not None:
        return fast(frames, delay_s)
    sleep = getattr(devices, "sleep", time.sleep)    # the devices' clock (the simulator's is virtual)
    out = []
    for f in frames:
        devices.projector.show(f)
        if delay_s > 0:
            sleep(delay_s)
        out.append(devices.camera.capture())
    return out


def _pose_from_corners(camera: PinholeCamera, obj: np.ndarray, ids: np.ndarray, uv: np.ndarray) -> np.ndarray:
    ok, rvec, tvec = cv2.solvePnP(obj[ids], uv.astype(np.float64), camera.K, camera.dist,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise CalibrationError("turntable: could not estimate the board's pose (solvePnP failed)")
    return make_T(rotvec_to_R(rvec.ravel()), tvec.ravel())


def calibrate_rig(devices, *, settings: CalibrationSettings = CalibrationSettings(),
                  place_board: Callable[[int, int], None], place_on_turntable: Callable[[], None] | None = None,
                  template: Rig | None = None, progress: Callable | None = None,
                  on_pose: Callable[[PoseCheck, np.ndarray], bool] | None = None) -> RigCalibration:
    """Run the whole calibration (module doc) and return the calibrated rig.

    Parameters
    ----------
    devices : has ``camera``, ``projector`` and ``turntable`` (None: no turntable step), as in
        :mod:`rangekit.rig.devices` (a :class:`rangekit.sim.SimRig` or the opened hardware).
    settings : board, number of poses, patterns, turntable angles.
    place_board : ``place_board(i, n)`` puts the board in pose i of n before it is captured.
    place_on_turntable : puts the board on the turntable (required when ``devices.turntable`` is set).
    template : a rig whose ``devices`` and ``capture`` sections are copied into the result; its
        ``capture.pattern_delay_s`` and ``capture.turntable_settle_s`` are waited on real hardware.
    progress : ``progress(msg, done=None, total=None)``.
    on_pose : ``on_pose(check, coverage)`` after each capture of a board pose, with its verdict
        (:func:`rangekit.calib.pose_feedback.check_pose`) and the coverage picture so far ((H, W, 3) uint8,
        :func:`~rangekit.calib.pose_feedback.coverage_image`); the pose is captured again (after
        ``place_board(i, n)``) when it returns True (a rejected pose to retake, or a kept one the person would
        rather redo), else a rejected pose is skipped. Rejected poses never enter the solve.

    Raises
    ------
    CalibrationError
        Too few usable poses, degenerate poses, no corners for the projector; the message says which views.
    """
    capture_settings = template.capture if template is not None else {}
    W, H = devices.projector.resolution
    spec = make_pattern_spec(settings.patterns, (W, H))
    light = _CodedLight(devices, spec, list(spec.frames()), spec.frame_names.index("white"),
                        float(capture_settings.get("pattern_delay_s", 0.0)))
    settle_s = float(capture_settings.get("turntable_settle_s", 0.0))
    seconds: dict[str, float] = {}
    t0, response_fit = time.time(), None
    place_board(0, settings.n_poses)
    if settings.measure_response:
        call_progress(progress, "projector response: grey levels")
        levels = np.linspace(0.0, 1.0, settings.response_levels)
        response_fit = measure_response(devices.projector, devices.camera, levels=levels)
        seconds["response"] = time.time() - t0
    response = None if response_fit is None else response_fit.response
    t1 = time.time()
    poses = _board_poses(light, settings, place_board, on_pose, response, progress)
    t2 = time.time()
    seconds["capture"] = t2 - t1
    pair = calibrate_pair(poses.cam_views, poses.proj_fits, settings.board.object_points(),
                          devices.camera.calibration.size, (W, H),
                          names=[f"pose {i + 1}" for i in range(settings.n_poses)], lens=LENS_MODELS[settings.lens])
    bundle, seconds["solve"] = pair.bundle, time.time() - t2
    axis, T_cam_world = None, np.eye(4)      # world = camera frame
    turntable = getattr(devices, "turntable", None)
    if turntable is not None:
        if place_on_turntable is None:
            raise CalibrationError("turntable: the rig has a turntable but no way to place the board on it "
                                   "(place_on_turntable)")
        t3 = time.time()
        place_on_turntable()
        axis, T_cam_world = _turntable(light, turntable, bundle, settings, response, settle_s, progress)
        seconds["turntable"] = time.time() - t3
    rig = _calibrated_rig(bundle, T_cam_world, axis is not None, template, response)
    seconds["total"] = time.time() - t0
    return RigCalibration(rig=rig, camera=pair.camera, projector=pair.projector, bundle=bundle, axis=axis,
                          response=response_fit, corner_std_projector=pair.corner_std_projector, seconds=seconds,
                          pose_checks=poses.checks, retaken=poses.retaken, lens=pair.lens.name)


@dataclass(frozen=True, eq=False)
class _CodedLight:
    """The coded light a calibration projects: the ``devices``, the pattern ``spec``, its ``frames`` and the index
    of its white frame (the board's corners are found in it), the wait after showing each frame (seconds)."""

    devices: object
    spec: object
    frames: list
    white_index: int
    delay_s: float

    def capture(self) -> list[np.ndarray]:
        """One capture of every frame (:func:`_capture`)."""
        return _capture(self.devices, self.frames, self.delay_s)


@dataclass(frozen=True, eq=False)
class _BoardPoses:
    """Per board pose the camera's corners (``cam_views``; a rejected pose's empty, with why), their projector
    coordinates (``proj_fits``; None if rejected) and its verdict (``checks``); how many captures were ``retaken``."""

    cam_views: list
    proj_fits: list
    checks: tuple
    retaken: int


def _board_poses(light: _CodedLight, settings: CalibrationSettings, place_board: Callable[[int, int], None],
                 on_pose: Callable | None, response, progress: Callable | None) -> _BoardPoses:
    """Each board pose placed (:func:`calibrate_rig`'s ``place_board``; the first is in place), captured, checked,
    taken again while ``on_pose`` asks (at most ``settings.max_attempts`` captures); a kept pose's corners and their
    projector coordinates from its decoded maps (integer Gray code, corrected for ``response``)."""
    n, board = settings.n_poses, settings.board
    size = light.devices.camera.calibration.size
    cam_views, proj_fits, checks, kept, retaken = [], [], [], [], 0
    for i in range(n):
        if i > 0:
            place_board(i, n)
        for attempt in range(max(1, settings.max_attempts)):
            call_progress(progress, f"board pose {i + 1}/{n}: {len(light.frames)} frames", i, n)
            images = light.capture()
            det = detect_board(images[light.white_index], board)
            check = check_pose(i, det, board, size, kept=kept, limits=settings.feedback)
            retake = False
            if on_pose is not None:
                shown = kept + [(det.ids, det.uv)] if check.accepted else kept
                retake = bool(on_pose(check, coverage_image(shown, size, det.uv, check.accepted)))
            if not retake or attempt == settings.max_attempts - 1:
                break
            retaken += 1
            place_board(i, n)
        checks.append(check)
        if check.accepted:
            kept.append((det.ids, det.uv))
            cam_views.append(Correspondences(det.ids, det.uv))
            dec = decode(images, light.spec, subpixel=False, response=response)
            proj_fits.append(corner_projector_coords(dec.proj_col, dec.proj_row, dec.confidence, det.uv,
                                                     radius=settings.corner_radius))
        else:
            cam_views.append(Correspondences(np.zeros(0, np.int64), np.zeros((0, 2)), check.reason))
            proj_fits.append(None)
    call_progress(progress, f"captured {n} board poses", n, n)
    return _BoardPoses(cam_views, proj_fits, tuple(checks), retaken)


def _turntable(light: _CodedLight, turntable, bundle: BundleResult, settings: CalibrationSettings, response,
               settle_s: float, progress: Callable | None) -> tuple[AxisFit, np.ndarray]:
    """The turntable phase, the board on the table: a capture at each of ``settings.turntable_angles_deg`` (waiting
    ``settle_s`` seconds on hardware), the board's pose at each by PnP, the axis fitted to the angles the table
    reached, the table top from the scene triangulated at the middle angle: (the axis fit, ``T_cam_table``)."""
    camera, projector = bundle.camera, bundle.projector
    obj = settings.board.object_points()
    angles = np.radians(settings.turntable_angles_deg)
    obs, poses, table_points = [], [], None
    mid = int(np.argmin(np.abs(angles - np.median(angles))))
    reached = angles.astype(np.float64).copy()
    for k, a in enumerate(angles):
        call_progress(progress, f"turntable {np.degrees(a):+.0f} deg ({k + 1}/{len(angles)})", k, len(angles))
        turntable.rotate_to(float(a))
        reached[k] = turntable.angle      # where the board says it stopped (a stepper rounds to a microstep)
        if settle_s > 0 and not hasattr(light.devices, "capture_sequence"):
            time.sleep(settle_s)
        images = light.capture()
        det = detect_board(images[light.white_index], settings.board)
        if not det.found:
            raise CalibrationError(f"turntable: the board is not found at {np.degrees(a):+.1f} deg "
                                   f"({det.reason}); mount it so the camera sees it at every angle")
        obs.append((det.ids, det.uv))
        poses.append(_pose_from_corners(camera, obj, det.ids, det.uv))
        if k == mid:
            dec = decode(images, light.spec, subpixel=False, response=response)
            tri = triangulate(camera, projector, dec.proj_col, dec.proj_row)
            table_points = tri.xyz.reshape(-1, 3)
    turntable.rotate_to(0.0)
    axis = fit_turntable_axis(camera, obj, reached, obs, poses)
    T_cam_table, _ = turntable_frame(axis, table_points)
    return axis, T_cam_table


def _calibrated_rig(bundle: BundleResult, T_cam_world: np.ndarray, turntable: bool, template: Rig | None,
                    response) -> Rig:
    """The rig of the bundle-adjusted devices in the world ``T_cam_world`` (the turntable frame, or the camera's),
    with the template's ``devices`` and ``capture`` sections and the measured projector response."""
    T_world_cam = invert_T(T_cam_world)
    return Rig(cameras=(bundle.camera.with_pose(T_world_cam),),
               projector=bundle.projector.with_pose(compose(T_world_cam, bundle.projector.T_world_cam)),
               T_world_table=np.eye(4) if turntable else None,
               devices=dict(template.devices) if template is not None else {},
               capture=dict(template.capture) if template is not None else {},
               projector_response=response)


def _axis_in_camera(rig: Rig) -> tuple[np.ndarray, np.ndarray]:
    """(direction, point) of the turntable axis in the main camera's frame."""
    T_cam_table = compose(rig.camera.T_cam_world, rig.T_world_table)
    return T_cam_table[:3, 2], T_cam_table[:3, 3]


def compare_rigs(calibrated: Rig, truth: Rig) -> dict:
    """Deviation of each calibrated parameter from ``truth`` (frame-independent quantities).

    Returns a dict: per device (``camera``, ``projector``) the relative errors of fx, fy, cx, cy (%) and the
    distortion differences; ``baseline_pct`` (camera-projector distance), ``rotation_deg`` (relative
    rotation of projector to camera); with turntables, ``axis_direction_deg`` (angle between the axes),
    ``axis_point_mm`` (distance of the calibrated table origin from the true axis line, in the camera
    frame) and ``table_origin_mm`` (distance between the table origins); ``gamma`` (calibrated - true).
    """
    out: dict = {}
    for key, c, t in (("camera", calibrated.camera, truth.camera), ("projector", calibrated.projector, truth.projector)):
        Kc, Kt = c.K, t.K
        d = {n: float((Kc[i, j] / Kt[i, j] - 1) * 100) for n, (i, j) in
             {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}.items()}
        d["pp_px"] = float(np.hypot(Kc[0, 2] - Kt[0, 2], Kc[1, 2] - Kt[1, 2]))
        n_d = max(len(c.dist), len(t.dist))
        dc, dt = np.zeros(n_d), np.zeros(n_d)
        dc[:len(c.dist)], dt[:len(t.dist)] = c.dist, t.dist
        d["dist_diff"] = (dc - dt).tolist()
        out[key] = d
    T_c = compose(calibrated.camera.T_cam_world, calibrated.projector.T_world_cam)
    T_t = compose(truth.camera.T_cam_world, truth.projector.T_world_cam)
    out["baseline_pct"] = float((np.linalg.norm(T_c[:3, 3]) / np.linalg.norm(T_t[:3, 3]) - 1) * 100)
    out["translation_mm"] = float(np.linalg.norm(T_c[:3, 3] - T_t[:3, 3]) * 1e3)
    out["rotation_deg"] = float(np.degrees(rotation_angle(T_c[:3, :3].T @ T_t[:3, :3])))
    if calibrated.T_world_table is not None and truth.T_world_table is not None:
        ac, pc = _axis_in_camera(calibrated)
        at, pt = _axis_in_camera(truth)
        out["axis_direction_deg"] = float(np.degrees(np.arccos(np.clip(ac @ at, -1.0, 1.0))))
        dp = pc - pt
        out["axis_point_mm"] = float(np.linalg.norm(dp - (dp @ at) * at) * 1e3)
        out["table_origin_mm"] = float(np.linalg.norm(dp) * 1e3)
    gc = calibrated.projector_response.gamma if calibrated.projector_response is not None else None
    gt = truth.projector_response.gamma if truth.projector_response is not None else None
    if gc is not None and gt is not None:
        out["gamma"] = float(gc - gt)
    return out


def comparison_lines(dev: dict) -> list[str]:
    """Human-readable lines for :func:`compare_rigs`'s dict."""
    lines = []
    for key in ("camera", "projector"):
        d = dev[key]
        lines.append(f"{key}: fx {d['fx']:+.4f}% fy {d['fy']:+.4f}% cx {d['cx']:+.4f}% cy {d['cy']:+.4f}% "
                     f"(principal point {d['pp_px']:.3f} px off); distortion diff "
                     f"{' '.join(f'{x:+.5f}' for x in d['dist_diff'])}")
    lines.append(f"camera-projector: baseline {dev['baseline_pct']:+.4f}%, translation {dev['translation_mm']:.3f} mm, "
                 f"rotation {dev['rotation_deg']:.4f} deg")
    if "axis_direction_deg" in dev:
        lines.append(f"turntable: axis direction {dev['axis_direction_deg']:.4f} deg, axis point "
                     f"{dev['axis_point_mm']:.3f} mm, table origin {dev['table_origin_mm']:.3f} mm")
    if "gamma" in dev:
        lines.append(f"projector gamma: {dev['gamma']:+.4f}")
    return lines
