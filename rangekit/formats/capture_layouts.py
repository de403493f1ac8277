"""Capture layouts as data: what each frame of another tool's capture folder is, so the folder decodes as it
lies on disk (issue 35; docs/real-captures.md gives each layout's frame table and its source).

A :class:`CaptureLayout` names the tool's frame files, the rangekit :class:`~rangekit.coded.patterns.PatternSpec`
of the same patterns, and for each frame of that spec the file that holds it, or how it is made when the
tool records no such frame (the white and black references of a phase-only codec: ``A + B`` and ``A - B`` of
its coarsest phase steps, exact for sinusoidal frames). :func:`arrange` puts the tool's frames into the
spec's order; everything after that (decoding, triangulation, filtering) is rangekit's own.

Presets (:data:`LAYOUTS`):

- ``slstudio:2x3`` (SLStudio's ``CodecPhaseShift2x3``, columns): ``frameSeq_00..05``: three steps of 16
  periods across the screen, then three steps of one period (the cue), each ``(1 + cos(2 pi x / pitch -
  2 pi k / 3)) / 2``: rangekit's ``phase`` method with periods (width, width / 16) and 3 steps each.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.coded.patterns import PatternSpec
from rangekit.errors import FileFormatError

__all__ = ["CaptureLayout", "LAYOUTS", "layout_files", "arrange"]

WHITE_FROM_STEPS, BLACK_FROM_STEPS = "A+B", "A-B"


@dataclass(frozen=True)
class CaptureLayout:
    name: str                                   # "slstudio:2x3"
    source: str                                 # the tool's file the layout is read from
    file_name: str                              # a frame's file name from its index, e.g. "frameSeq_{:02d}.bmp"
    n_files: int
    spec: Callable[[int, int], PatternSpec]     # the same patterns as a rangekit spec, from the projector size
    frames: tuple                               # per frame of the spec: a file index, or WHITE_/BLACK_FROM_STEPS
    steps_for_references: tuple[int, ...] = ()  # the files whose phase steps make the synthesized references


def _slstudio_2x3(width: int, height: int) -> PatternSpec:
    return PatternSpec("phase", width, height, ("columns",),
                       {"steps": 3, "fine_steps": 3, "periods": [width, width / 16]})


LAYOUTS = {
    "slstudio:2x3": CaptureLayout("slstudio:2x3", "slstudio src/codec/CodecPhaseShift2x3.cpp, pstools.cpp",
                                  "frameSeq_{:02d}.bmp", 6, _slstudio_2x3,
                                  (WHITE_FROM_STEPS, BLACK_FROM_STEPS, 3, 4, 5, 0, 1, 2), (3, 4, 5)),
}


def layout_files(folder: str | Path, layout: CaptureLayout) -> list[Path]:
    """The layout's frame files in ``folder``, in the tool's order; FileFormatError naming the first missing."""
    paths = [Path(folder) / layout.file_name.format(k) for k in range(layout.n_files)]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise FileFormatError(f"{folder}: expected the {layout.n_files} frames of {layout.name} "
                              f"({paths[0].name} ... {paths[-1].name}), found {missing[0]} missing"
                              f"{f' and {len(missing) - 1} more' if len(missing) > 1 else ''}")
    return paths


def arrange(images: Sequence[np.ndarray], layout: CaptureLayout, width: int, height: int
            ) -> tuple[np.ndarray, PatternSpec]:
    """The tool's frames (``images``, its order) as a stack in the order of the spec for a ``width`` x ``height``
    projector, and that spec. Synthesized references keep the frames' dtype (clipped to its range)."""
    from rangekit.coded.phase import phase_from_steps

    if len(images) != layout.n_files:
        raise FileFormatError(f"{layout.name}: expected {layout.n_files} frames, found {len(images)}")
    spec = layout.spec(width, height)
    first = np.asarray(images[0])
    made = {}
    if layout.steps_for_references:
        _, B, A = phase_from_steps([images[k] for k in layout.steps_for_references])
        top = np.iinfo(first.dtype).max if first.dtype.kind in "ui" else np.inf
        made = {WHITE_FROM_STEPS: np.clip(A + B, 0, top).astype(first.dtype),
                BLACK_FROM_STEPS: np.clip(A - B, 0, top).astype(first.dtype)}
    stack = np.stack([made[f] if isinstance(f, str) else np.asarray(images[f]) for f in layout.frames])
    if len(stack) != len(spec.frame_names):
        raise FileFormatError(f"{layout.name}: the layout gives {len(stack)} frames, its spec has "
                              f"{len(spec.frame_names)}")
    return stack, spec
