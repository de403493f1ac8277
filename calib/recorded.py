"""Calibration from recorded sequences: board poses someone else's tool recorded under its coded light.

Moreno and Taubin's method ("Simple, accurate, and robust projector-camera calibration", 3DIMPVT 2012), with
rangekit's pose checks and bundle adjustment. Per board pose (:func:`measure_pose`):

1. the board's corners in the pose's lit image (:func:`rangekit.boards.detect_board`; a checkerboard with
   ``rows + cols`` even is accepted, its ids known up to a half turn, which poses solved each alone do not
   mind), the board read as given or with its cols and rows swapped (:func:`board_readings`), as OpenCV's,
   procam-calibration's and SLStudio's calibrators take its size either way round;
2. the pose's checks (:func:`rangekit.calib.pose_feedback.check_pose`: corners, size, tilt, reprojection), and
   one more: enough corners lit by the projector;
3. each corner's projector coordinates from the decoded maps around it, by one of
   :data:`rangekit.calib.camera.CORNER_FITS`:
   "quadratic", rangekit's own robust local quadratic regression
   (:func:`rangekit.calib.projector.corner_projector_coords`, the hardware calibration's), or "homography",
   Moreno and Taubin's local homography (:func:`rangekit.calib.local_homography.local_homography_coords`;
   docs/calibration.md notes it is patented, US 10008007). On SLStudio's five recorded poses both give the
   same rig (projector RMS 0.304 and 0.307 px alone, docs/real-captures.md).

Then (:func:`calibrate_recorded`) the camera alone, the projector alone and both bundle-adjusted together
(:func:`rangekit.calib.pair.calibrate_pair`). The rig's world is the camera's frame; there is no turntable
and no projector response (the recordings hold neither).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rangekit.boards import Board, detect_board
from rangekit.calib.camera import CORNER_FITS, LENS_MODELS, Correspondences
from rangekit.calib.local_homography import local_homography_coords
from rangekit.calib.pair import calibrate_pair
from rangekit.calib.pose_feedback import FeedbackLimits, PoseCheck, check_pose
from rangekit.calib.procedure import RigCalibration
from rangekit.calib.projector import CornerFit, corner_projector_coords
from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError
from rangekit.rig.rig_file import Rig

__all__ = ["RecordedPose", "board_readings", "measure_pose", "refused_pose", "calibrate_recorded", "MIN_POSES"]

MIN_POSES = 3        # Zhang's method: three board poses at least, for each device


@dataclass(frozen=True, eq=False)
class RecordedPose:
    """One recorded board pose reduced to what the calibration needs.

    ``name``: how messages name it (its folder); ``check``: the verdict (:class:`PoseCheck`, ``reason`` "" when
    kept); ``corners``: the camera's corners (ids, uv in camera pixels; none when rejected); ``projector``: their
    projector coordinates (NaN rows where not lit), None when rejected; ``board``: the reading of the board the
    corners were found under (:func:`board_readings`; their ids are its corners), None when not found.
    """

    name: str
    check: PoseCheck
    corners: Correspondences
    projector: CornerFit | None
    board: Board | None = None

    def line(self) -> str:
        """The pose's verdict, named: "calseq1: kept: 117 corners, ...", "calseq2: rejected: board not found"."""
        return f"{self.name}: {self.check.line().split(': ', 1)[1]}"


def board_readings(board: Board) -> tuple[Board, ...]:
    """The readings of ``board`` a recorded pose is searched under, in turn: as given, then (a checkerboard that is
    not square) with its cols and rows swapped (:meth:`rangekit.boards.Board.transposed`).

    rangekit's board frame starts at the dark corner square, so a checkerboard whose cols and rows are both even
    (SLStudio's 14 x 10) is found only under the print's own reading: the other one has a light square there.
    The rig does not depend on the reading: the board's corners are the same points in either frame."""
    if board.kind != "checkerboard" or board.cols == board.rows:
        return (board,)
    return (board, board.transposed())


def _detect(lit: np.ndarray, readings: Sequence[Board]):
    """(the board's reading it was found under or None, the detection; when not found, the reason names each
    reading tried)."""
    tried = []
    for reading in readings:
        det = detect_board(lit, reading, symmetric_ok=True)
        if det.found:
            return reading, det
        tried.append((reading, det.reason))
    first = tried[0][1]
    if len(tried) > 1 and all(reason == "board not found" for _, reason in tried):
        sizes = " or ".join(f"{b.cols} x {b.rows}" for b, _ in tried)
        first = f"board not found, read as {sizes} squares"
    elif len(tried) > 1:
        first = "; ".join(f"{reason} (read as {b.cols} x {b.rows} squares)" for b, reason in tried)
    if readings[0].kind == "checkerboard" and first.startswith("board not found"):
        first += " (a checkerboard is found whole or not at all: is all of it inside the image?)"
    return None, dataclasses.replace(det, reason=first)


def refused_pose(index: int, name: str, reason: str) -> RecordedPose:
    """A pose refused before its corners could be looked for (its frames do not decode), with the reason."""
    nan = float("nan")
    return RecordedPose(name, PoseCheck(index, 0, nan, nan, nan, "", nan, reason), _none(reason), None)


def _none(reason: str) -> Correspondences:
    return Correspondences(np.zeros(0, np.int64), np.zeros((0, 2)), reason)


def measure_pose(index: int, name: str, lit: np.ndarray, proj_col: np.ndarray, proj_row: np.ndarray,
                 board: Board | Sequence[Board], *, confidence: np.ndarray | None = None,
                 kept: Sequence[tuple[np.ndarray, np.ndarray]] = (), limits: FeedbackLimits = FeedbackLimits(),
                 corners: str = CORNER_FITS[0], radius: int = 10) -> RecordedPose:
    """Steps 1-3 of the module doc for one board pose.

    Parameters
    ----------
    index : the pose's place in the calibration, from 0.
    name : its name in messages.
    lit : (H, W) uint8/uint16 image the board's corners are found in (the mean of a pose's frames:
        :func:`rangekit.app.calibrate_recorded.board_image`).
    proj_col, proj_row : (H, W) float decoded projector column and row, NaN where the decoder masked the pixel.
    confidence : (H, W) float in [0, 1], the decoder's (the quadratic fit weights by it); None: 1 where decoded.
    board : the printed board, searched under each of its readings (:func:`board_readings`); or the readings to
        try, in turn (one: the reading earlier poses were found under). ``RecordedPose.board`` is the one used.
    kept : (ids, uv) of the poses kept before this one (the reprojection check fits a camera to them).
    limits : when a pose is rejected; ``min_corners`` also counts the corners the projector lights.
    corners : one of :data:`rangekit.calib.camera.CORNER_FITS`.
    radius : half-window of the corner fits, camera pixels (10: SLStudio's; 21 x 21 pixels).
    """
    if corners not in CORNER_FITS:
        raise CalibrationError(f"corners must be one of {', '.join(CORNER_FITS)}, found {corners!r}")
    height, width = proj_col.shape
    readings = board_readings(board) if isinstance(board, Board) else tuple(board)
    reading, det = _detect(lit, readings)
    check = check_pose(index, det, reading or readings[0], (width, height), kept=kept, limits=limits)
    if not check.accepted:
        return RecordedPose(name, check, _none(check.reason), None, reading)
    if corners == "homography":
        fit = local_homography_coords(proj_col, proj_row, det.uv, radius=radius)
    else:
        conf = np.isfinite(proj_col) & np.isfinite(proj_row) if confidence is None else confidence
        fit = corner_projector_coords(proj_col, proj_row, conf.astype(np.float32), det.uv, radius=radius)
    lit_corners = int(fit.ok.sum())
    if lit_corners < limits.min_corners:
        reason = (f"only {lit_corners} of its {len(det.ids)} corners in the projector's light, at least "
                  f"{limits.min_corners} needed")
        return RecordedPose(name, dataclasses.replace(check, reason=reason), _none(reason), None, reading)
    return RecordedPose(name, check, Correspondences(det.ids, det.uv), fit, reading)


def calibrate_recorded(poses: Sequence[RecordedPose], board: Board, camera_size: tuple[int, int],
                       projector_size: tuple[int, int], *, lens: str = "k1k2p",
                       seconds: dict | None = None) -> RigCalibration:
    """The camera and the projector from measured poses (:func:`measure_pose`), bundle-adjusted together.

    Parameters
    ----------
    poses : every recorded pose, kept or rejected, in order.
    board : the printed board, in the reading the poses' corners were found under (``RecordedPose.board``).
    camera_size, projector_size : (width, height) pixels; the projector's in the pixels its code counts.
    lens : a name of :data:`rangekit.calib.camera.LENS_MODELS`.
    seconds : time already spent, by stage (decoding); "solve" and "total" are added.

    Returns
    -------
    RigCalibration
        ``rig``: the camera (world = its frame) and the projector; no turntable, no projector response.

    Raises
    ------
    CalibrationError
        Fewer than :data:`MIN_POSES` poses kept (the message lists each rejected pose and why), too few left
        after the reprojection outliers, or degenerate poses.
    """
    if lens not in LENS_MODELS:
        raise CalibrationError(f"lens must be one of {', '.join(LENS_MODELS)}, found {lens!r}")
    seconds = dict(seconds or {})
    kept = [p for p in poses if p.check.accepted]
    if len(kept) < MIN_POSES:
        why = "; ".join(p.line() for p in poses if not p.check.accepted)
        raise CalibrationError(f"only {len(kept)} of {len(poses)} board poses usable, at least {MIN_POSES} needed"
                               + (f" ({why})" if why else "") + "; record more poses with the whole board in "
                               "view and in the projector's light")
    t0 = time.time()
    pair = calibrate_pair([p.corners for p in poses], [p.projector for p in poses], board.object_points(),
                          camera_size, projector_size, names=[p.name for p in poses], lens=LENS_MODELS[lens])
    seconds["solve"] = time.time() - t0
    seconds["total"] = sum(seconds.values())
    camera: PinholeCamera = pair.bundle.camera
    rig = Rig(cameras=(camera,), projector=pair.bundle.projector, T_world_table=None, devices={}, capture={},
              projector_response=None)
    return RigCalibration(rig=rig, camera=pair.camera, projector=pair.projector, bundle=pair.bundle, axis=None,
                          response=None, corner_std_projector=pair.corner_std_projector, seconds=seconds,
                          pose_checks=tuple(p.check for p in poses), lens=lens, pose_names=tuple(p.name for p in poses))
