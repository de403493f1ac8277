"""The Calibrate page's second way in: a rig calibrated from board poses another tool recorded (SLStudio's, a
procam tool's), one folder per pose, as ``rangekit calibrate --captures DIR... --pattern LAYOUT --projector WxH``
does (:func:`rangekit.app.calibrate_recorded.calibrate_recordings`), on a thread.

The folders are named relative to the sessions folder (a glob such as ``calib/pose_*``, or names separated by
spaces or commas) and confined to it (:func:`rangekit.ui.paths.confined`); the rig file is written there too.
"""

from __future__ import annotations

from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.jobs.base import Job
from rangekit.ui.jobs.notifier import Topic
from rangekit.ui.paths import confined

__all__ = ["RecordedCalibrationJob", "parse_projector_size", "pose_folders"]


def parse_projector_size(text: str) -> tuple[int, int]:
    """(width, height) of ``WxH``, or the one-line error the page shows next to the field."""
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
        if 0 < w <= 100_000 and 0 < h <= 100_000:
            return w, h
    except ValueError:
        pass
    raise RangekitError(f"projector: expected WIDTHxHEIGHT in pixels, e.g. 1824x1140, found {text!r}")


def pose_folders(sessions: Path, text: str) -> list[Path]:
    """The pose folders ``text`` names under ``sessions``: a glob (``*``, ``?``, ``[``) or names separated by
    spaces or commas, each confined to the folder; sorted as named (a glob: by name)."""
    names = [n for n in str(text).replace(",", " ").split() if n]
    if not names:
        raise RangekitError("captures: name the pose folders under the sessions folder, e.g. calib/pose_*")
    folders: list[Path] = []
    for name in names:
        if any(c in name for c in "*?["):
            confined(sessions, name.split("*")[0].split("?")[0].split("[")[0] or ".")   # refuse ../ and /abs early
            matches = sorted(p for p in Path(sessions).resolve().glob(name) if p.is_dir())
            if not matches:
                raise RangekitError(f"captures: {name}: no folder matches under the sessions folder")
            folders += [confined(sessions, str(p.relative_to(Path(sessions).resolve()))) for p in matches]
        else:
            folder = confined(sessions, name)
            if not folder.is_dir():
                raise RangekitError(f"captures: {name}: no such folder under the sessions folder")
            folders.append(folder)
    return folders


class RecordedCalibrationJob(Job):
    """The latest calibration from recorded captures under ``sessions``."""

    WHAT, TOPIC = "calibration from recorded captures", Topic.RECORDED

    def __init__(self, sessions: Path, notifier=None) -> None:
        super().__init__(notifier)
        self.sessions = Path(sessions).resolve()

    def snapshot(self) -> dict:
        from rangekit.formats.layouts import LAYOUTS

        return {**super().snapshot(), "layouts": sorted(LAYOUTS)}

    def start(self, captures: str, pattern: str, projector: str, out: str, cols=10, rows=7, square_mm=20.0,
              replace: bool = False) -> dict:
        """Check the inputs (each error names its field), then calibrate on a thread. The board: ``cols`` x ``rows``
        squares of ``square_mm`` millimetres (``rangekit calibrate --cols --rows --square-mm``). An existing ``out``
        is replaced only when ``replace`` says so (the command line's ``--force``)."""
        from rangekit.boards import Board
        from rangekit.formats.layouts import LAYOUTS

        folders = pose_folders(self.sessions, captures)
        size = parse_projector_size(projector)
        if pattern not in LAYOUTS:
            raise RangekitError(f"pattern: {pattern!r}: unknown capture layout; known: {', '.join(sorted(LAYOUTS))}")
        if not isinstance(out, str) or not out.endswith(".json"):
            raise RangekitError(f"out: expected a rig file name ending in .json, found {out!r}")
        rig_file = confined(self.sessions, out)
        if rig_file.exists() and not replace:
            raise RangekitError(f"out: {out} exists under the sessions folder; choose another name or tick "
                                "'replace it'")
        for name, v, low in (("cols", cols, 3), ("rows", rows, 3)):
            if isinstance(v, bool) or not isinstance(v, int) or not low <= v <= 60:
                raise RangekitError(f"{name}: expected a whole number of squares 3-60, found {v!r}")
        if isinstance(square_mm, bool) or not isinstance(square_mm, (int, float)) or not 0 < square_mm < 1000:
            raise RangekitError(f"square_mm: expected the square's side in millimetres (0-1000), found {square_mm!r}")
        board = Board(cols=cols, rows=rows, square=square_mm / 1000.0)
        self.begin(poses=len(folders))
        self.launch(self._run, folders, pattern, size, rig_file, board, replace)
        return self.snapshot()

    def _run(self, folders: list[Path], pattern: str, size: tuple[int, int], rig_file: Path, board,
             replace: bool) -> dict:
        from rangekit.app.calibrate_recorded import calibrate_recordings

        cal = calibrate_recordings(rig_file, folders, pattern=pattern, projector_size=size, board=board,
                                   force=replace, progress=self.say, report=self.say)
        for line in cal.result.summary_lines():
            self.say(line)
        return {"rig_file": rig_file.name}
