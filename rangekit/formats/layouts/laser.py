"""A laser-line turntable recording as it lies on disk (issue 50, Deliver 2): a Ciclop/Horus/FabScan-style rig's
frames, one camera, one or more line lasers, a turntable, recorded by another tool (or by hand) and read here.

The layout is data, as the structured-light capture layouts are (:mod:`rangekit.formats.layouts.layout`): a
:class:`LaserLayout` says which frames a step holds (the laser-off frame if recorded, then one frame per laser,
each laser alone on) and how they lie:

- ``laser:folders``: a subfolder per frame kind, ``off/`` (optional), ``laser0/``, ``laser1/``, ... each holding one
  image per step, the steps in numeric order of the names (``0.png, 1.png, ..., 10.png``, zero-padded or not;
  :func:`rangekit.formats.capture.natural_key`);
- ``laser:off-laser0-laser1`` (and the other interleaved presets): one folder, the frames in numeric order of the
  names, each step's frames one after the other in the order the preset names them (rangekit's scan and Horus take
  them so: move, every laser off, laser 1 on alone, laser 2 on alone).

Step angles: uniform (``step_deg``, the turntable's step, ``rangekit reconstruct --step-deg``), or a per-step table
``steps.csv`` in the recording's folder when they are not (one row ``step,angle_deg`` per step, numbered from 0 in
the frames' order; ``#`` starts a comment; a header row ``step,angle_deg`` is allowed). The table, when there, is
the one source of the angles: a step angle given as well is refused.

Errors are one line naming the folder or file, what was expected and what was found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError, UsageError, shown
from rangekit.formats.capture import natural_key
from rangekit.formats.layouts.layout import FRAME_SUFFIXES
from rangekit.io import read_png

__all__ = ["LaserLayout", "LASER_LAYOUTS", "LaserStep", "LaserRecording", "STEPS_FILE", "read_laser_recording",
           "read_step_frames", "steps_table_text", "laser_layout"]

#: The per-step table of a recording whose step angles are not uniform.
STEPS_FILE = "steps.csv"
#: Lasers a recording may hold (as :data:`rangekit.laser.sequence.MAX_LASERS`).
_MAX_LASERS = 8


@dataclass(frozen=True)
class LaserLayout:
    """How a laser recording's frames lie (module doc).

    name : the preset's name (``laser:...``).
    source : who records so, one line.
    n_lasers : laser frames per step; None: as many ``laserK/`` subfolders as the folder holds (``folders``).
    off : the laser-off frame is recorded (first of each step); None: ``off/`` read when the folder has it.
    folders : a subfolder per frame kind; else one folder, each step's frames consecutive.
    """

    name: str
    source: str
    n_lasers: int | None = None
    off: bool | None = None
    folders: bool = False

    def kinds(self, n_lasers: int, off: bool) -> list[str]:
        """A step's frames in recording order: ``["off", "laser0", "laser1"]``."""
        return (["off"] if off else []) + [f"laser{k}" for k in range(n_lasers)]

    def frame_path(self, folder: str | Path, step: int, kind: str, n_lasers: int, off: bool) -> Path:
        """Where this layout keeps step ``step``'s frame ``kind`` (a writer's names: zero-padded numbers)."""
        folder = Path(folder)
        if self.folders:
            return folder / kind / f"{step:04d}.png"
        kinds = self.kinds(n_lasers, off)
        return folder / f"{step * len(kinds) + kinds.index(kind):05d}.png"


def _interleaved(n: int, off: bool) -> LaserLayout:
    kinds = LaserLayout("", "").kinds(n, off)
    name = "laser:" + "-".join(kinds)
    what = ("the laser-off frame, then " if off else "no laser-off frame; ") + " then ".join(
        f"laser {k + 1} alone" for k in range(n))
    return LaserLayout(name, f"one folder, frames in numeric order of the names, per step {what} (rangekit's scan, "
                             "Horus/Ciclop, FabScan order)", n, off)


#: Every laser recording layout by name.
LASER_LAYOUTS = {layout.name: layout for layout in (
    LaserLayout("laser:folders", "off/ (optional), laser0/, laser1/, ...: one frame per step in each, numeric order "
                                 "of the names", folders=True),
    *(_interleaved(n, off) for off in (True, False) for n in (1, 2)))}


def laser_layout(name: str | LaserLayout) -> LaserLayout:
    """The preset ``name`` (a LaserLayout passes through); UsageError naming the known ones."""
    if isinstance(name, LaserLayout):
        return name
    if name not in LASER_LAYOUTS:
        raise UsageError(f"--pattern {name}: not a laser recording layout; known: {', '.join(LASER_LAYOUTS)}")
    return LASER_LAYOUTS[name]


@dataclass(frozen=True)
class LaserStep:
    """One turntable step: its ``index`` (from 0), ``angle`` (radians), the laser-off frame's file (None: not
    recorded) and one file per laser."""

    index: int
    angle: float
    off: Path | None
    lasers: tuple[Path, ...]


@dataclass(frozen=True)
class LaserRecording:
    """A recording read: the ``steps`` in order, where their angles came from (``angles_from``), the layout."""

    folder: Path
    layout: LaserLayout
    steps: tuple[LaserStep, ...]
    n_lasers: int
    has_off: bool
    angles_from: str

    @property
    def angles(self) -> np.ndarray:
        """(n_steps,) radians."""
        return np.array([s.angle for s in self.steps])

    def line(self) -> str:
        """"rec: 100 steps of 2 laser(s) and the laser-off frame (laser:folders), angles from steps.csv"."""
        off = "and the laser-off frame" if self.has_off else "without laser-off frames"
        span = math.degrees(float(np.ptp(self.angles))) if len(self.steps) > 1 else 0.0
        return (f"{self.folder}: {len(self.steps)} steps of {self.n_lasers} laser(s) {off} ({self.layout.name}), "
                f"angles from {self.angles_from}, spanning {span:.1f} deg")


def _images(folder: Path) -> list[Path]:
    files = [p for p in folder.iterdir() if p.suffix.lower() in FRAME_SUFFIXES and not p.name.startswith(".")
             and p.is_file()] if folder.is_dir() else []
    return sorted(files, key=lambda p: (natural_key(p), p.name))


def _folder_frames(folder: Path, layout: LaserLayout) -> tuple[list[list[Path]], int, bool]:
    """``(frames per step, n_lasers, off)`` of a ``folders`` layout."""
    n = layout.n_lasers
    if n is None:
        n = 0
        while n < _MAX_LASERS and (folder / f"laser{n}").is_dir():
            n += 1
    off = (folder / "off").is_dir() if layout.off is None else layout.off
    kinds = layout.kinds(n, off)
    lists = {kind: _images(folder / kind) for kind in kinds}
    if n == 0 or not any(lists.values()):
        raise FileFormatError(f"{folder}: no frames: expected the subfolders of {layout.name}, laser0/, laser1/, ... (and "
                              f"off/ if recorded), each with one image ({', '.join(FRAME_SUFFIXES)}) per step, found "
                              f"{'none of them' if n == 0 else 'no images in ' + ', '.join(k + '/' for k in kinds)}")
    counts = {kind: len(files) for kind, files in lists.items()}
    if len(set(counts.values())) != 1:
        most = max(counts.values())
        short = ", ".join(f"{k}/ holds {c}" for k, c in counts.items() if c != most)
        raise FileFormatError(f"{folder}: expected one frame per step in each of {', '.join(k + '/' for k in kinds)} "
                              f"({most} steps), found {short}")
    steps = [[lists[kind][i] for kind in kinds] for i in range(next(iter(counts.values())))]
    return steps, n, off


def _interleaved_frames(folder: Path, layout: LaserLayout) -> tuple[list[list[Path]], int, bool]:
    """``(frames per step, n_lasers, off)`` of an interleaved layout."""
    kinds = layout.kinds(layout.n_lasers, bool(layout.off))
    files = _images(folder)
    if not files:
        raise FileFormatError(f"{folder}: no frames: expected the images of {layout.name} ({', '.join(FRAME_SUFFIXES)}), "
                              f"{len(kinds)} per step ({', '.join(kinds)}) in numeric order of the names, found none")
    if len(files) % len(kinds):
        raise FileFormatError(f"{folder}: {len(files)} frames ({files[0].name} ... {files[-1].name}) are not a whole "
                              f"number of steps of {len(kinds)} ({', '.join(kinds)}, {layout.name}); a frame is missing "
                              "or one more is there")
    steps = [files[i:i + len(kinds)] for i in range(0, len(files), len(kinds))]
    return steps, layout.n_lasers, bool(layout.off)


def _parse_steps_table(path: Path, n_steps: int) -> np.ndarray:
    """(n_steps,) radians from ``steps.csv``; FileFormatError naming the file (and line) for a bad or missing row."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{path}: not a readable text table ({exc.__class__.__name__}); expected rows "
                              "'step,angle_deg'") from None
    angles: dict[int, float] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line or line.replace(" ", "").lower() == "step,angle_deg":
            continue
        cells = [c.strip() for c in line.split(",")]
        try:
            step, angle = int(cells[0]), float(cells[1])
            if len(cells) != 2 or not math.isfinite(angle):
                raise ValueError
        except (ValueError, IndexError):
            raise FileFormatError(f"{path}:{number}: expected 'step,angle_deg' (a step number and a finite angle in "
                                  f"degrees), found {shown(raw.strip())}") from None
        if not 0 <= step < n_steps:
            raise FileFormatError(f"{path}:{number}: step {step}: the recording has {n_steps} steps, numbered 0 to "
                                  f"{n_steps - 1}")
        if step in angles:
            raise FileFormatError(f"{path}:{number}: step {step} given twice")
        angles[step] = math.radians(angle)
    missing = [k for k in range(n_steps) if k not in angles]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise FileFormatError(f"{path}: no row for step {missing[0]}{more}; expected one row 'step,angle_deg' for "
                              f"each of the {n_steps} steps, 0 to {n_steps - 1}")
    return np.array([angles[k] for k in range(n_steps)])


def read_laser_recording(folder: str | Path, layout: str | LaserLayout, *, step_deg: float | None = None
                         ) -> LaserRecording:
    """The steps of the recording in ``folder`` under ``layout`` (a name of :data:`LASER_LAYOUTS`), their angles
    from ``steps.csv`` or ``step_deg`` (module doc). No pixel is read here (:func:`read_step_frames` does).

    Raises
    ------
    UsageError : an unknown layout; both or neither of ``steps.csv`` and ``step_deg``; a non-finite or zero step.
    FileFormatError : not a folder, no frames, a frame missing (counts that are not one per step), a bad or
        missing row of the step table.
    """
    layout = laser_layout(layout)
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: expected a folder of laser frames ({layout.name}), found "
                              f"{'a file' if folder.exists() else 'nothing'}")
    steps, n, off = (_folder_frames if layout.folders else _interleaved_frames)(folder, layout)
    table = folder / STEPS_FILE
    if table.is_file():
        if step_deg is not None:
            raise UsageError(f"--step-deg {step_deg:g}: {table} gives each step's angle; give one of them")
        angles, source = _parse_steps_table(table, len(steps)), str(table)
    else:
        if step_deg is None:
            raise UsageError(f"{folder}: no {STEPS_FILE} and no step angle: give --step-deg DEG (the turntable's step, "
                             f"uniform) or write {STEPS_FILE} (one row 'step,angle_deg' per step)")
        if not (math.isfinite(step_deg) and step_deg != 0 and abs(step_deg) <= 360):
            raise UsageError(f"--step-deg {step_deg!r}: expected a finite, non-zero angle of at most 360 degrees")
        angles, source = np.radians(step_deg) * np.arange(len(steps)), f"--step-deg {step_deg:g}"
    out = tuple(LaserStep(i, float(angles[i]), files[0] if off else None, tuple(files[1:] if off else files))
                for i, files in enumerate(steps))
    return LaserRecording(folder, layout, out, n, off, source)


def _described(img: np.ndarray) -> str:
    """"640x480 RGB uint8"."""
    return f"{img.shape[1]}x{img.shape[0]} {'RGB' if img.ndim == 3 else 'grey'} {img.dtype}"


def read_step_frames(step: LaserStep) -> tuple[np.ndarray | None, tuple[np.ndarray, ...]]:
    """The step's laser-off image (None when not recorded) and laser images, each as recorded (RGB or grey);
    FileFormatError naming the file for an unreadable one or one of another size than the step's first."""
    paths = ([step.off] if step.off is not None else []) + list(step.lasers)
    images = [read_png(p) for p in paths]
    for p, img in zip(paths[1:], images[1:]):
        if img.shape != images[0].shape or img.dtype != images[0].dtype:
            raise FileFormatError(f"{p}: image is {_described(img)}, but {paths[0]} is {_described(images[0])}; a "
                                  "step's frames need one size, depth and number of channels")
    return (images[0] if step.off is not None else None), tuple(images[1:] if step.off is not None else images)


def steps_table_text(angles_deg) -> str:
    """The text of a ``steps.csv`` holding ``angles_deg`` (one per step, degrees)."""
    rows = [f"{k},{float(a):.9g}" for k, a in enumerate(angles_deg)]
    return "step,angle_deg\n" + "\n".join(rows) + "\n"
