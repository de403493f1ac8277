"""``rangekit calibrate --captures DIR [DIR ...] --pattern PRESET --projector WxH``: a rig from board poses another
tool recorded under its coded light, one folder per pose in a capture layout (:mod:`rangekit.formats.layouts`).

Each folder is read (:func:`rangekit.formats.layouts.folder_frames`: the layout's frames, no more, no fewer, under
the tool's names or, without them, in numeric order of the names),
put in the layout's spec order (:func:`~rangekit.formats.layouts.arrange`), decoded
(:func:`rangekit.coded.decode.decode`) and measured (:func:`rangekit.calib.recorded.measure_pose`: the board's
corners in the mean of its frames (:func:`board_image`), the pose's checks, each corner's projector coordinates
from a local fit over the decoded maps); only the corners are kept, so any number of poses fits in memory. Then the camera and the
projector are calibrated and bundle-adjusted together (:func:`rangekit.calib.recorded.calibrate_recorded`) and
the rig file written, world = the camera's frame. ``coverage.png`` beside it shows the camera image the kept
poses' corners cover, as the hardware calibration's does.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.app.calibrate import Calibration
from rangekit.boards import Board
from rangekit.errors import DecodeError, FileFormatError, UsageError
from rangekit.io import write_png
from rangekit.progress import call_progress
from rangekit.rig.rig_file import save_rig

__all__ = ["calibrate_recordings", "board_image", "board_image_source", "board_reading_line"]


def board_image_source(layout, width: int, height: int) -> str:
    """What the board's corners are found in: the mean of the pose's frames, as the tool recorded them."""
    n = layout.n_files(width, height)
    first, last = (layout.file_name.format(k, index=k, camera=1) for k in (layout.first_index,
                                                                             layout.first_index + n - 1))
    return f"mean of its {n} frames ({first} ... {last})"


def board_image(frames: np.ndarray) -> np.ndarray:
    """(H, W) uint16: the mean of a pose's frames ((K, H, W[, 3]) as recorded), scaled to 16 bits.

    Every frame of a coded sequence lights the board on average half the time, so the mean is a lit board with
    the camera's noise averaged over all of them: on SLStudio's five poses the camera's reprojection RMS is
    0.280 px from the mean of the 12 frames, 0.284 from the cue's A + B, 0.286 from the fine steps' modulation
    (the image SLStudio itself detects corners in).
    """
    grey = frames.astype(np.float32).mean(axis=-1) if frames.ndim == 4 else frames.astype(np.float32)
    mean = grey.mean(axis=0)
    top = float(mean.max()) or 1.0
    return np.clip(np.rint(mean * (65535.0 / top)), 0, 65535).astype(np.uint16)


def board_reading_line(reading: Board, given: Board, where: str) -> str:
    """How the board was read, in one line: "board read as 14 x 10 squares (given 10 x 14), found so in calseq1"."""
    how = "as given" if reading == given else f"(given {given.cols} x {given.rows})"
    return f"board read as {reading.cols} x {reading.rows} squares {how}, found so in {where}"


def _names(captures: Sequence[Path]) -> list[str]:
    """Each pose's name: its folder's name, or the path as given where two folders share a name."""
    short = [p.name or str(p) for p in captures]
    return short if len(set(short)) == len(short) else [str(p) for p in captures]


def calibrate_recordings(out: str | Path, captures: Sequence[str | Path], *, pattern: str,
                         projector_size: tuple[int, int], board: Board, lens: str = "k1k2p",
                         corners: str = "quadratic", force: bool = False, progress: Callable | None = None,
                         report: Callable[[str], object] | None = None) -> Calibration:
    """Calibrate the camera and the projector from recorded board poses; write the rig file ``out``.

    Parameters
    ----------
    out : the rig file to write (JSON).
    captures : one folder per board pose, each holding the layout's frames.
    pattern : the layout's name (:data:`rangekit.formats.layouts.LAYOUTS`); it must code columns and rows.
    projector_size : (width, height) of the projector's screen in the pixels the tool drew its patterns in.
    board : the printed board (a checkerboard may have ``rows + cols`` even), its cols and rows either way round:
        each pose is searched under both readings (:func:`rangekit.calib.recorded.board_readings`) until one is
        found, then under that one; ``report`` gets which.
    lens : a name of :data:`rangekit.calib.camera.LENS_MODELS`.
    corners : how each corner's projector coordinates are fitted, one of
        :data:`rangekit.calib.camera.CORNER_FITS` ("quadratic", rangekit's own; "homography", Moreno and
        Taubin's).
    report : gets one line per pose (kept, or rejected and why) and where the corners are found.

    Raises
    ------
    UsageError
        ``out`` exists (without ``force``), an unknown layout, one that does not code both axes, a capture
        that is not a folder, fewer than 3 folders.
    FileFormatError
        A folder without the layout's frames (one missing, more than it has), images of another size than
        the other poses'.
    CalibrationError
        Fewer than 3 poses usable (each rejected pose named with its reason), degenerate poses.
    """
    from rangekit.calib.pose_feedback import coverage_image
    from rangekit.calib.recorded import calibrate_recorded

    out = Path(out)
    layout, width, height = _checked_layout(out, force, pattern, corners, projector_size)
    folders = _checked_folders(captures, pattern)
    names = _names(folders)
    if report is not None:
        report(f"{len(folders)} board poses, {pattern} ({layout.source}); corners found in each pose's "
               f"{board_image_source(layout, width, height)}; their projector coordinates by a local {corners} "
               "fit")
    t0 = time.time()
    measured = _measured_poses(folders, names, pattern, layout, width, height, board, corners, report, progress)
    result = calibrate_recorded(measured.poses, measured.board, measured.camera_size, (width, height), lens=lens,
                                seconds={"decode": time.time() - t0})
    # Written with the rig, once it is calibrated: a failed run leaves no coverage.png (issue 48: it replaced
    # an earlier calibration's), nothing is recorded live to watch.
    last = measured.poses[-1]
    write_png(out.parent / "coverage.png", coverage_image(measured.kept, measured.camera_size,
                                                          last.corners.uv if last.check.accepted else None,
                                                          last.check.accepted))
    save_rig(result.rig, out)
    return Calibration(result, None, [])


def _checked_layout(out: Path, force: bool, pattern: str, corners: str, projector_size) -> tuple:
    """``(layout, width, height)``: the capture layout named ``pattern`` and the ``projector_size`` it was drawn
    on; UsageError for an existing ``out`` without ``force``, an unknown layout or corner fit, a layout that does
    not code the projector's columns and rows with a white frame."""
    from rangekit.calib.camera import CORNER_FITS
    from rangekit.formats.layouts import LAYOUTS

    if out.exists() and not force:
        raise UsageError(f"--out {out}: exists; choose another file or pass --force to overwrite it")
    if pattern not in LAYOUTS:
        raise UsageError(f"--pattern {pattern}: unknown capture layout; known: {', '.join(sorted(LAYOUTS))}")
    if corners not in CORNER_FITS:
        raise UsageError(f"--corners {corners}: expected one of {', '.join(CORNER_FITS)}")
    layout = LAYOUTS[pattern]
    width, height = (int(v) for v in projector_size)
    spec = layout.spec(*layout.decoded_size(width, height))
    if set(spec.axes) != {"columns", "rows"} or "white" not in spec.frame_names:
        raise UsageError(f"--pattern {pattern}: codes only the projector's {' and '.join(spec.axes)}; calibrating "
                         "the projector needs its columns and rows at every board corner (e.g. "
                         "slstudio:calibration)")
    return layout, width, height


def _checked_folders(captures: Sequence[str | Path], pattern: str) -> list[Path]:
    """The pose folders; UsageError for fewer than the poses a calibration needs, one that is not a folder, or one
    given twice."""
    from rangekit.calib.recorded import MIN_POSES

    folders = [Path(c) for c in captures]
    if len(folders) < MIN_POSES:
        raise UsageError(f"--captures: {len(folders)} folder(s); at least {MIN_POSES} board poses are needed "
                         "(Zhang's method), 5-20 is typical")
    for folder in folders:
        if not folder.is_dir():
            raise UsageError(f"--captures {folder}: expected a folder of {pattern} frames, found "
                             f"{'a file' if folder.exists() else 'nothing'}")
    counts = Counter(f.resolve() for f in folders)
    twice = [(next(f for f in folders if f.resolve() == where), n) for where, n in counts.items() if n > 1]
    if twice:
        raise UsageError(f"--captures: {', '.join(f'{f} given {n} times' for f, n in twice)}; give each board pose "
                         f"once ({len(counts)} distinct folders of the {len(folders)} given)")
    return folders


@dataclass(frozen=True, eq=False)
class _MeasuredPoses:
    """Every pose folder measured: the ``poses`` (:class:`rangekit.calib.recorded.RecordedPose`, in order), the
    kept ones' corners (``kept``: (ids, uv) each), the camera's (width, height) and the ``board`` as it was read."""

    poses: list
    kept: list
    camera_size: tuple[int, int]
    board: Board


def _measured_poses(folders: list[Path], names: list[str], pattern: str, layout, width: int, height: int,
                    board: Board, corners: str, report: Callable[[str], object] | None,
                    progress: Callable | None) -> _MeasuredPoses:
    """Each folder read, put in the layout's spec order, decoded and measured, one at a time (only its corners
    kept); a folder that does not decode is a refused pose, not a failed run. The board is searched both ways round
    until one pose finds it, then that way alone. FileFormatError for images of another size than the first
    pose's."""
    from rangekit.calib.pose_feedback import FeedbackLimits
    from rangekit.calib.recorded import board_readings, measure_pose, refused_pose
    from rangekit.coded.decode import decode
    from rangekit.formats.capture import read_stack
    from rangekit.formats.layouts import arrange, folder_frames, in_projector_pixels
    from rangekit.formats.layouts.frame_files import NUMERIC_ORDER

    limits = FeedbackLimits()
    poses, kept, camera_size = [], [], None
    readings = board_readings(board)      # both ways round until a pose's board is found, then that one
    for i, (folder, name) in enumerate(zip(folders, names)):
        call_progress(progress, f"pose {i + 1}/{len(folders)}: {name}", i, len(folders))
        found = folder_frames(folder, layout, width, height)
        if found.order == NUMERIC_ORDER and report is not None:      # not the tool's names: say which files
            report(f"{name}: {found.line()}")
        frames = read_stack(found.files, what=f"a {pattern} capture")
        size = (frames.shape[2], frames.shape[1])
        if camera_size is None:
            camera_size = size
        elif size != camera_size:
            raise FileFormatError(f"{folder}: images are {size[0]}x{size[1]}, those of {folders[0]} "
                                  f"{camera_size[0]}x{camera_size[1]}; every pose must come from the same camera")
        lit = board_image(frames)
        stack, spec = arrange(list(frames), layout, width, height)
        del frames
        try:
            dec = decode(stack, spec)
        except DecodeError as exc:                  # an unlit or wrong folder: this pose refused, not the run
            pose = refused_pose(i, name, f"not decoded: {exc}")
        else:
            dec = in_projector_pixels(dec, layout, width, height)
            pose = measure_pose(i, name, lit, dec.proj_col, dec.proj_row, readings, confidence=dec.confidence,
                                kept=kept, limits=limits, corners=corners)
            if pose.board is not None and len(readings) > 1:
                readings = (pose.board,)
                if report is not None:
                    report(board_reading_line(pose.board, board, name))
        del stack
        poses.append(pose)
        if pose.check.accepted:
            kept.append((pose.corners.ids, pose.corners.uv))
        if report is not None:
            report(pose.line())
    call_progress(progress, f"decoded {len(folders)} board poses", len(folders), len(folders))
    return _MeasuredPoses(poses, kept, camera_size, readings[0])
