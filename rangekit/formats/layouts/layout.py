"""A capture layout: what each frame of another tool's capture folder is, so the folder decodes as it lies on
disk (issue 35; docs/real-captures.md gives each preset's frame table and the source it was read from).

A :class:`CaptureLayout` names the tool's frame files, the rangekit :class:`~rangekit.coded.patterns.PatternSpec`
of the same patterns, and for each frame of that spec where it comes from:

- a file index (an ``int``): the tool recorded that frame;
- :data:`WHITE_FROM_STEPS` / :data:`BLACK_FROM_STEPS`: the references of a phase-only codec, which records
  none, made as ``A + B`` and ``A - B`` of its coarsest phase steps (exact for sinusoidal frames);
- :class:`Inverse` ``(k)``: the inverse of a binary frame the tool projected without one, made as
  ``white + black - frame k``. rangekit's bit rule, ``frame - inverse > 0``, then reads
  ``2 frame > white + black``: the frame is nearer white than black, the rule of tools without inverses.
- :data:`WHITE_FROM_PAIRS` / :data:`BLACK_FROM_PAIRS`: the references of a Gray code recorded without white
  and black whose tool masks a pixel by its pairs' contrast (RoomAlive: every pair of ``pairs_for_references``
  differing by more than a threshold): black is the darkest of those frames, white black plus the smallest
  ``|frame - inverse|`` of the pairs, so that rangekit's ``white - black`` test is the tool's test, exactly.

``mirror``: the tool's frames are mirror images (a Kinect v2's, flipped left to right by its SDK); :func:`arrange`
flips them back, so that the camera is a pinhole camera of the room (the rig file describes it so).

``blocks``: per axis, how the tool's code counts projector pixels (:class:`AxisBlocks`): in blocks of ``size``
pixels (a Gray code whose least significant bits are left out: its top bits are the Gray code of
``column >> k``, since ``gray(u) >> k == gray(u >> k)``), from ``offset`` pixels before the first (a Gray code
centred on the screen, as Moreno and Taubin's). The spec is for the projector of those codes, and
:func:`decoding_projector` the projector model whose pixels they are: exact, not a resampling.

:func:`arrange` puts the tool's frames into the spec's order; everything after it (decoding, triangulation,
filtering) is rangekit's own, with the layout's ``view_options`` (keywords of
:func:`rangekit.coded.reconstruct.reconstruct_view`) where a tool's captures need other settings than
rangekit's own, each with the measurement that chose it in the tool's module.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.coded.patterns import PatternSpec
from rangekit.errors import FileFormatError

__all__ = ["AxisBlocks", "CaptureLayout", "Inverse", "WHITE_FROM_STEPS", "BLACK_FROM_STEPS", "WHITE_FROM_PAIRS",
           "BLACK_FROM_PAIRS", "FRAME_SUFFIXES",
           "layout_files", "tool_names", "arrange", "decoding_projector", "from_decoding_projector", "in_projector_pixels",
           "tool_frames"]

WHITE_FROM_STEPS, BLACK_FROM_STEPS = "A+B", "A-B"
WHITE_FROM_PAIRS, BLACK_FROM_PAIRS = "black + min |P - I|", "min of pairs"

#: The image formats a tool's frames may come in (8 or 16 bit, grey or colour; JPEG as OpenCV's sample data).
FRAME_SUFFIXES = (".bmp", ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".pgm", ".ppm")


@dataclass(frozen=True)
class Inverse:
    """The inverse of file ``file``'s binary frame, made as ``white + black - frame``."""

    file: int


@dataclass(frozen=True)
class AxisBlocks:
    """How a code counts the pixels of one projector axis: ``code = (pixel + offset) // size``; code ``c`` is lit
    on pixels ``size c - offset ... size c - offset + size - 1``, centre ``size c - offset + (size - 1) / 2``."""

    size: int = 1
    offset: int = 0

    def codes(self, n: int) -> int:
        """How many codes an axis of ``n`` pixels needs (the spec's size on that axis)."""
        return (n - 1 + self.offset) // self.size + 1


PLAIN = (AxisBlocks(), AxisBlocks())


@dataclass(frozen=True)
class CaptureLayout:
    """One tool's capture folder: its files, the same patterns as a rangekit spec, and each spec frame's source.

    ``spec`` and ``frames`` are functions of the projector's (width, height) in the tool's own pixels, since
    how many bits a Gray code has depends on it; ``n_files`` likewise.
    """

    name: str                                          # "slstudio:2x3"
    source: str                                        # the tool's source files the layout was read from
    file_name: str                                     # a frame's file from its index, e.g. "frameSeq_{:02d}.bmp";
                                                       # may name {index} and {camera} (1, 2: a stereo capture)
    n_files: Callable[[int, int], int]                 # how many files, from the projector size
    spec: Callable[[int, int], PatternSpec]            # the spec, for the (binned) projector size
    frames: Callable[[int, int], tuple]                # per spec frame: file index, Inverse, or WHITE_/BLACK_...
    steps_for_references: tuple[int, ...] = ()         # the files whose phase steps make the synthesized references
    blocks: Callable[[int, int], tuple] = lambda w, h: PLAIN   # (columns, rows) AxisBlocks of the code
    view_options: dict = field(default_factory=dict)   # reconstruct_view's keywords for the tool's captures
    first_index: int = 0                               # the first file's index (OpenCV's and Moreno-Taubin's: 1)
    other_names: tuple[str, ...] = ()                  # file names tried when file_name's first file is missing
    pairs_for_references: Callable[[int, int], tuple] = lambda w, h: ()   # (frame, inverse) file pairs whose
                                                       # smallest contrast makes WHITE_/BLACK_FROM_PAIRS
    mirror: bool = False                               # the frames are mirror images: arrange flips them

    def decoded_size(self, width: int, height: int) -> tuple[int, int]:
        """The size of the projector the spec codes: the codes of each axis (:class:`AxisBlocks`)."""
        cols, rows = self.blocks(width, height)
        return cols.codes(width), rows.codes(height)


def layout_files(folder: str | Path, layout: CaptureLayout, width: int, height: int, *, camera: int = 1
                 ) -> list[Path]:
    """The layout's frame files in ``folder`` for a ``width`` x ``height`` projector, in the tool's order (of
    camera ``camera`` where the names carry one); the tool's names first, then the same names as any of
    :data:`FRAME_SUFFIXES` (a folder converted to another format). FileFormatError naming the first missing."""
    n = layout.n_files(width, height)
    names = tool_names(folder, layout, camera)
    found = next((name for name in names if (Path(folder) / name.format(layout.first_index, index=layout.first_index,
                                                                          camera=camera)).is_file()), names[0])
    indices = range(layout.first_index, layout.first_index + n)
    paths = [Path(folder) / found.format(k, index=k, camera=camera) for k in indices]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise FileFormatError(f"{folder}: expected the {n} frames of {layout.name} for a {width}x{height} "
                              f"projector ({paths[0].name} ... {paths[-1].name}), found {missing[0]} missing"
                              f"{f' and {len(missing) - 1} more' if len(missing) > 1 else ''}")
    extra = Path(folder) / found.format(indices.stop, index=indices.stop, camera=camera)
    if extra.is_file():
        raise FileFormatError(f"{folder}: expected the {n} frames of {layout.name} for a {width}x{height} "
                              f"projector, found more ({extra.name}): is the projector size right?")
    return paths


def tool_names(folder: str | Path, layout: CaptureLayout, camera: int = 1) -> tuple[str, ...]:
    """The name patterns the layout's frames may have in ``folder`` (``str.format`` of the index, and ``index``,
    ``camera``): the tool's names, then the same as any of :data:`FRAME_SUFFIXES`, a prefix the user chose put in."""
    given = (layout.file_name, *layout.other_names)
    names = given + tuple(name.rsplit(".", 1)[0] + suffix for name in given for suffix in FRAME_SUFFIXES
                          if not name.endswith(suffix))
    return tuple(_with_prefix(folder, name, layout.first_index, camera) for name in names)


def _with_prefix(folder: str | Path, name: str, first: int, camera: int) -> str:
    """``name`` with its ``*`` (a prefix the user chose, as OpenCV's samples take) replaced by the one prefix
    of the folder's first frame; FileFormatError if two prefixes have one."""
    if "*" not in name:
        return name
    head, tail = name.split("*", 1)
    first_name = tail.format(first, index=first, camera=camera)
    matches = sorted(p.name[len(head): len(p.name) - len(first_name)]
                     for p in Path(folder).glob(head + "*" + first_name) if p.is_file())
    if len(matches) > 1:
        raise FileFormatError(f"{folder}: expected one capture ({head}*{first_name}), found {len(matches)}: "
                              f"{', '.join(head + m + first_name for m in matches[:3])}; give each its own folder")
    return head + (matches[0] if matches else "*").replace("{", "{{").replace("}", "}}") + tail


def arrange(images: Sequence[np.ndarray], layout: CaptureLayout, width: int, height: int
            ) -> tuple[np.ndarray, PatternSpec]:
    """The tool's frames (``images``, its order) as a stack in the order of the spec for a ``width`` x ``height``
    projector (the tool's pixels), and that spec (for :meth:`CaptureLayout.decoded_size`). Made frames keep
    the frames' dtype, clipped to its range."""
    from rangekit.coded.phase import phase_from_steps

    n = layout.n_files(width, height)
    if len(images) != n:
        raise FileFormatError(f"{layout.name}: expected {n} frames for a {width}x{height} projector, found "
                              f"{len(images)}")
    spec = layout.spec(*layout.decoded_size(width, height))
    frames = layout.frames(width, height)
    if layout.mirror:
        images = [np.fliplr(np.asarray(image)) for image in images]
    first = np.asarray(images[0])
    top = np.iinfo(first.dtype).max if first.dtype.kind in "ui" else np.inf
    made = {}
    if layout.steps_for_references:
        _, B, A = phase_from_steps([images[k] for k in layout.steps_for_references])
        made = {WHITE_FROM_STEPS: np.clip(A + B, 0, top).astype(first.dtype),
                BLACK_FROM_STEPS: np.clip(A - B, 0, top).astype(first.dtype)}
    pairs = layout.pairs_for_references(width, height)
    if pairs:
        black, low = np.asarray(images[pairs[0][0]]).copy(), None
        for p, i in pairs:
            P, I = np.asarray(images[p]), np.asarray(images[i])
            np.minimum(black, np.minimum(P, I), out=black)
            contrast = np.abs(P.astype(np.int32) - I)
            low = contrast if low is None else np.minimum(low, contrast, out=low)
        made = {BLACK_FROM_PAIRS: black, WHITE_FROM_PAIRS: (black + low).astype(first.dtype)}

    def frame(source) -> np.ndarray:
        if isinstance(source, Inverse):
            white, black = (frame(frames[spec.frame_names.index(name)]) for name in ("white", "black"))
            inverse = white.astype(np.int32) + black - np.asarray(images[source.file])
            return np.clip(inverse, 0, top).astype(first.dtype)
        return made[source] if isinstance(source, str) else np.asarray(images[source])

    stack = np.stack([frame(f) for f in frames])
    if len(stack) != len(spec.frame_names):
        raise FileFormatError(f"{layout.name}: the layout gives {len(stack)} frames, its spec has "
                              f"{len(spec.frame_names)}")
    return stack, spec


def decoding_projector(projector: PinholeCamera, layout: CaptureLayout) -> PinholeCamera:
    """The projector as the layout's code sees it: its pixels are the code's blocks (:class:`AxisBlocks`).

    Code ``c`` is centred on pixel ``u = s c - o + (s - 1) / 2``, so ``fx' = fx / s`` and
    ``cx' = (cx + o - (s - 1) / 2) / s`` (rows alike): the same rays, exactly. ``projector`` itself where the
    code counts single pixels from 0.
    """
    cols, rows = layout.blocks(projector.width, projector.height)
    if (cols, rows) == PLAIN:
        return projector
    K = projector.K.copy()
    for axis, blocks in ((0, cols), (1, rows)):
        K[axis, axis] /= blocks.size
        K[axis, 2] = (K[axis, 2] + blocks.offset - (blocks.size - 1) / 2) / blocks.size
    width, height = layout.decoded_size(projector.width, projector.height)
    return PinholeCamera(K, width, height, projector.dist, projector.T_world_cam, projector.name)


def from_decoding_projector(decoding: PinholeCamera, projector: PinholeCamera, layout: CaptureLayout) -> PinholeCamera:
    """:func:`decoding_projector` undone: ``projector`` (the rig file's) with ``decoding``'s pose and, mapped back
    to its own pixels, its focal lengths and principal point (a refined decoding projector back into a rig file)."""
    cols, rows = layout.blocks(projector.width, projector.height)
    K = decoding.K.copy()
    for axis, blocks in ((0, cols), (1, rows)):
        K[axis, axis] *= blocks.size
        K[axis, 2] = K[axis, 2] * blocks.size - blocks.offset + (blocks.size - 1) / 2
    return PinholeCamera(K, projector.width, projector.height, projector.dist, decoding.T_world_cam, projector.name)


def in_projector_pixels(decoded, layout: CaptureLayout, width: int, height: int):
    """A :class:`~rangekit.coded.result.DecodeResult` of the layout's spec with its coordinates (and their stds)
    in the ``width`` x ``height`` projector's pixels: each code at its block's centre (:class:`AxisBlocks`)."""
    from dataclasses import replace

    cols, rows = layout.blocks(width, height)
    if (cols, rows) == PLAIN:
        return decoded

    def pixels(coord, blocks):
        return (blocks.size * coord.astype(np.float64) - blocks.offset + (blocks.size - 1) / 2).astype(np.float32)

    return replace(decoded, proj_col=pixels(decoded.proj_col, cols), proj_row=pixels(decoded.proj_row, rows),
                   col_std=None if decoded.col_std is None else decoded.col_std * np.float32(cols.size),
                   row_std=None if decoded.row_std is None else decoded.row_std * np.float32(rows.size))


def tool_frames(layout: CaptureLayout, width: int, height: int) -> list[np.ndarray]:
    """The frames the tool projects, in its file order, as (height, width) uint8 images of a ``width`` x
    ``height`` projector: what the simulator renders to make a capture in the tool's layout (a file made by
    rangekit, as a phase codec's references, is none of them). Each comes from the spec's frame of that file,
    its codes spread over their blocks."""
    spec = layout.spec(*layout.decoded_size(width, height))
    cols, rows = layout.blocks(width, height)
    col_code = (np.arange(width) + cols.offset) // cols.size
    row_code = (np.arange(height) + rows.offset) // rows.size
    files = {f: name for f, name in zip(layout.frames(width, height), spec.frame_names) if isinstance(f, int)}
    frames = []
    for k in range(layout.n_files(width, height)):
        if k not in files:
            raise FileFormatError(f"{layout.name}: file {k} holds none of the spec's frames")
        frames.append(spec.frame_by_name(files[k])[np.ix_(row_code, col_code)])
    return frames
