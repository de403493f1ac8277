"""Which files of a capture are its frames, and in which order (issue 47 item 5), however the capture is given:

- a folder holding the tool's own names (:func:`~rangekit.formats.layouts.layout.layout_files`): one camera's,
  or both cameras' where the names carry the camera (OpenCV's ``pattern_cam1_im*`` and ``pattern_cam2_im*``);
- a folder holding none of them and exactly the layout's number of image files (:data:`FRAME_SUFFIXES`) under
  any names: taken in the natural numeric order of the names (:func:`rangekit.formats.capture.natural_key`:
  ``1.jpg, 2.jpg, ..., 10.jpg``, zero-padded or not, as SLStudio's QCollator sorts in numeric mode);
- image files: a glob rangekit expands (``'caps/*.png'``, quoted) or the shell expanded (in its own,
  lexicographic order: ``1.png 10.png 11.png 2.png``), in numeric order of the names; one camera per glob, or
  per folder of the files given;
- OpenCV's image list (:func:`~rangekit.formats.layouts.opencv.read_image_list`): the list's order.

:func:`capture_frames` gives one :class:`FrameFiles` per camera; :meth:`FrameFiles.line` says in one line which
files were taken, in which order, from where. A count that is not the layout's is refused in one line naming the
folder (or glob, or list), the expected and the found count; images of two sizes are refused when read
(:func:`rangekit.formats.capture.read_stack`).
"""

from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from rangekit.errors import ConfigError, FileFormatError
from rangekit.formats.capture import natural_key
from rangekit.formats.layouts.layout import FRAME_SUFFIXES, CaptureLayout, layout_files, tool_names
from rangekit.formats.layouts.opencv import read_image_list

__all__ = ["FrameFiles", "capture_frames", "folder_frames", "NUMERIC_ORDER"]

NUMERIC_ORDER = "numeric order of the names"
_GLOB_CHARACTERS = frozenset("*?[")


@dataclass(frozen=True)
class FrameFiles:
    """One camera's frame files in the tool's order: ``order`` says how it was found (the tool's names, the
    numeric order of other names, an image list's order), ``source`` where from (a folder, a glob, a list)."""

    camera: int
    files: tuple[Path, ...]
    order: str
    source: str

    def line(self) -> str:
        """"camera 1: 44 frames 1.jpg ... 44.jpg (numeric order of the names) from caps/left"."""
        return (f"camera {self.camera}: {len(self.files)} frames {self.files[0].name} ... {self.files[-1].name} "
                f"({self.order}) from {self.source}")


def _sorted(files) -> tuple[Path, ...]:
    return tuple(sorted(files, key=lambda p: (str(p.parent), natural_key(p), p.name)))


def _expected(layout: CaptureLayout, width: int, height: int) -> str:
    return f"the {layout.n_files(width, height)} frames of {layout.name} for a {width}x{height} projector"


def folder_frames(folder: str | Path, layout: CaptureLayout, width: int, height: int, *, camera: int = 1
                  ) -> FrameFiles:
    """Camera ``camera``'s frames in ``folder``: under the tool's names if the folder holds any of them (then
    exactly as :func:`layout_files`: one missing or one more is refused), else its image files, as many as the
    layout has, in numeric order of their names. FileFormatError naming the folder, the expected and the found."""
    folder = Path(folder)
    try:
        return FrameFiles(camera, tuple(layout_files(folder, layout, width, height, camera=camera)),
                          f"{layout.name}'s names", str(folder))
    except FileFormatError:
        n = layout.n_files(width, height)
        images = [p for p in folder.iterdir() if p.suffix.lower() in FRAME_SUFFIXES and not p.name.startswith(".")
                  and p.is_file()] if folder.is_dir() else []
        indices = range(layout.first_index, layout.first_index + n + 1)
        tools = {name.format(k, index=k, camera=camera) for name in tool_names(folder, layout, camera) for k in indices}
        if not images or tools & {p.name for p in images}:
            raise                                   # the tool's names, one missing or more: layout_files says which
        if len(images) != n:
            first, last = (tool_names(folder, layout, camera)[0].format(k, index=k, camera=camera)
                           for k in (indices[0], indices[-2]))
            raise FileFormatError(f"{folder}: expected {_expected(layout, width, height)} ({first} ... {last}, or "
                                  f"{n} image files of any names, taken in numeric order), found {len(images)} image "
                                  "files") from None
        return FrameFiles(camera, _sorted(images), NUMERIC_ORDER, str(folder))


def _sources(items: Sequence[str]) -> list:
    """Each capture given, as a folder (Path) or (where, files): a glob's matches, or the image files given of
    one folder (the shell's expansion of a glob)."""
    sources, loose = [], {}
    for item in items:
        path = Path(item)
        if path.is_dir():
            sources.append(path)
        elif path.is_file():
            if path.suffix.lower() not in FRAME_SUFFIXES:
                raise FileFormatError(f"{item}: expected an image file ({', '.join(FRAME_SUFFIXES)}), a folder or "
                                      f"an image list, found a {path.suffix or 'suffixless'} file among other captures")
            where = str(path.parent)
            if where not in loose:
                loose[where] = []
                sources.append((where, loose[where]))
            loose[where].append(path)
        elif _GLOB_CHARACTERS & set(item):
            files = [Path(f) for f in glob.glob(item) if Path(f).suffix.lower() in FRAME_SUFFIXES and Path(f).is_file()]
            if not files:
                raise FileFormatError(f"{item}: expected image files ({', '.join(FRAME_SUFFIXES)}) matching this "
                                      "pattern, found none")
            sources.append((item, files))
        else:
            raise FileFormatError(f"{item}: expected a capture folder, image files or an image list, found nothing")
    return sources


def capture_frames(captures: Sequence[str | Path], layout: CaptureLayout, width: int, height: int, *,
                   cameras: int = 1) -> tuple[FrameFiles, ...]:
    """Each camera's frame files (module doc) from ``captures`` as given on the command line: one folder (one
    camera; or both where the layout's names carry the camera), one folder, glob or folder's files per camera,
    or one image list. ``cameras``: how many the rig needs (1: with a projector, 2: a pair).

    Raises FileFormatError (a count that is not the layout's, nothing found) or ConfigError (captures for
    another number of cameras), each in one line naming the folder, the expected and the found."""
    n = layout.n_files(width, height)
    items = [str(c) for c in captures]
    if len(items) == 1 and Path(items[0]).is_file() and Path(items[0]).suffix.lower() not in FRAME_SUFFIXES:
        frames = tuple(FrameFiles(k + 1, tuple(files), "the image list's order", items[0])
                       for k, files in enumerate(read_image_list(items[0])))
        _check_cameras([f.source for f in frames], cameras, items[0])
        for f in frames:
            if len(f.files) != n:
                raise FileFormatError(f"{items[0]}: expected {_expected(layout, width, height)} for camera "
                                      f"{f.camera}, found {len(f.files)} listed")
    else:
        sources = _sources(items)
        if len(sources) == 1 and cameras == 2:
            _check_both_cameras(sources[0], layout, items[0])
            frames = tuple(folder_frames(sources[0], layout, width, height, camera=k) for k in (1, 2))
        else:
            _check_cameras([str(s) if isinstance(s, Path) else s[0] for s in sources], cameras, items[0])
            frames = tuple(_frames(source, layout, width, height, k + 1) for k, source in enumerate(sources))
    _refuse_shared_files(frames)
    return frames


def _refuse_shared_files(frames: tuple[FrameFiles, ...]) -> None:
    """ConfigError when two cameras' lists name the same files (an image list whose camera 2 repeats camera 1's,
    one folder given twice): matched with themselves they make a silently wrong cloud (issue 48)."""
    if len(frames) < 2:
        return
    first, second = ({str(Path(f).resolve()) for f in fr.files} for fr in frames[:2])
    shared = first & second
    if shared:
        raise ConfigError(f"{frames[1].source}: camera 2's frames include {len(shared)} of camera 1's files (e.g. "
                          f"{sorted(shared)[0]}): each camera needs its own capture")


def _check_cameras(sources: list[str], cameras: int, given: str) -> None:
    if len(sources) != cameras:
        rig = "two cameras and no projector" if cameras == 2 else "a camera and a projector"
        raise ConfigError(f"{given}: expected the captures of {cameras} camera(s), for a rig with {rig}; found "
                          f"{len(sources)}: {', '.join(sources)}")


def _check_both_cameras(source, layout: CaptureLayout, given: str) -> None:
    """One capture for two cameras: a folder holding camera 2's files under the tool's names, else ConfigError."""
    first = layout.first_index
    carries = "{camera}" in layout.file_name
    if carries and isinstance(source, Path) and any((source / name.format(first, index=first, camera=2)).is_file()
                                                    for name in tool_names(source, layout, 2)):
        return
    both = (f", or one folder with {layout.name}'s names for both ("
            f"{', '.join(layout.file_name.format(first, index=first, camera=k) for k in (1, 2))} ...)" if carries else "")
    raise ConfigError(f"{given}: expected two cameras' captures (a folder or glob per camera{both}), found one "
                      "camera's")


def _frames(source, layout: CaptureLayout, width: int, height: int, camera: int) -> FrameFiles:
    if isinstance(source, Path):
        return folder_frames(source, layout, width, height, camera=camera)
    where, files = source
    n = layout.n_files(width, height)
    if len(files) != n:
        raise FileFormatError(f"{where}: expected {_expected(layout, width, height)}, found {len(files)} image files")
    return FrameFiles(camera, _sorted(files), NUMERIC_ORDER, where)
