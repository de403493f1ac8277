"""One coded-light capture to a cloud (``rangekit reconstruct`` and ``rk.reconstruct``): the images, the rig and
the pattern set from a capture folder, or given, decoded and triangulated by
:func:`rangekit.coded.reconstruct.reconstruct_view`; another tool's capture folder in its own layout
(:func:`reconstruct_tool_capture`), with a camera and a projector or with two cameras
(:func:`rangekit.stereo.coded_pair.reconstruct_pair`)."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.coded.reconstruct import Reconstruction, reconstruct_view
from rangekit.errors import ConfigError, InputError, naming
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.surface.cloud import PointCloud

__all__ = ["reconstruct", "reconstruct_capture", "reconstruct_tool_capture"]


def reconstruct(images_or_folder, rig: Rig | str | Path | None = None, pattern: PatternSpec | str | None = None, *,
                method: str = "auto", subpixel: bool = True) -> PointCloud:
    """The cloud of one coded-light capture, in the rig's world frame (metres).

    ``images_or_folder``: a capture folder (its images ``000.png ...``, and its ``patterns.json`` and
    ``rig.json`` when ``pattern`` or ``rig`` are not given) or one loaded
    (:func:`rangekit.formats.capture.load_capture`), a list of image files, or the images as one
    (K, H, W[, 3]) array or a list of (H, W[, 3]) arrays. ``rig``: a :class:`Rig` or a rig file.
    ``pattern``: a :class:`PatternSpec` or a method name (:data:`rangekit.coded.patterns.PATTERN_METHODS`,
    made for the rig's projector). ``method``: triangulation (``"auto"``, ``"ray-plane"``, ``"ray-ray"``).

    Raises ConfigError naming what is missing (no rig with a projector, no pattern set), FileFormatError for
    an unreadable image, PatternError when the images do not fit the pattern set.
    """
    return reconstruct_capture(images_or_folder, rig, pattern, method=method, subpixel=subpixel).cloud


def reconstruct_capture(images_or_folder, rig: Rig | str | Path | None = None,
                        pattern: PatternSpec | str | None = None, *, method: str = "auto",
                        subpixel: bool = True, view_options: dict | None = None) -> Reconstruction:
    """:func:`reconstruct` with what the decoding and the triangulation found (``Reconstruction``);
    ``view_options``: more keyword arguments of :func:`rangekit.coded.reconstruct.reconstruct_view` (a
    capture layout's, :attr:`rangekit.formats.layouts.CaptureLayout.view_options`)."""
    images, folder_rig, folder_spec, full_scale, where = _images(images_or_folder)
    if isinstance(rig, (str, Path)):
        rig = load_rig(rig)
    rig = rig if rig is not None else folder_rig
    if rig is None or rig.projector is None:
        raise ConfigError(f"{where}: no rig with a projector; give rig= (a Rig or a rig file"
                          f"{', or put rig.json in the folder' if folder_spec is not None or where != 'images' else ''})")
    if isinstance(pattern, str):
        pattern = make_pattern_spec(pattern, (rig.projector.width, rig.projector.height))
    spec = pattern if pattern is not None else folder_spec
    if spec is None:
        raise ConfigError(f"{where}: no pattern set; give pattern= (a PatternSpec or a method name) or put "
                          "patterns.json in the folder")
    with naming(where):
        return reconstruct_view(images, spec, rig.camera, rig.projector, subpixel=subpixel, method=method,
                                full_scale=full_scale, response=rig.projector_response, **(view_options or {}))


def _images(source) -> tuple[np.ndarray, Rig | None, PatternSpec | None, float | None, str]:
    """(images, the folder's rig, the folder's pattern set, full scale, what to name in errors)."""
    from rangekit.formats.capture import Capture, list_images, load_capture, read_stack

    if isinstance(source, (str, Path)) and Path(source).is_dir():
        source = load_capture(source)
    if isinstance(source, Capture):
        return source.images, source.rig, source.spec, source.full_scale, str(source.folder)
    if isinstance(source, np.ndarray):
        return source, None, None, None, "images"
    if isinstance(source, Sequence) and source and all(isinstance(s, (str, Path)) for s in source):
        return read_stack(list_images(source)), None, None, None, str(Path(source[0]).parent)
    if isinstance(source, Sequence) and source and all(isinstance(s, np.ndarray) for s in source):
        return np.stack(source), None, None, None, "images"
    raise InputError(f"images_or_folder: expected a capture folder, image files or image arrays, found "
                     f"{type(source).__name__}" + (f" {source!r}" if isinstance(source, (str, Path)) else ""))


def reconstruct_tool_capture(captures: Sequence[str | Path], preset: str, rig: Rig, *,
                             projector_size: tuple[int, int] | None = None, subpixel: bool = True,
                             method: str = "auto", report: Callable[[str], object] | None = None):
    """Another tool's capture as it lies on disk (:data:`rangekit.formats.layouts.LAYOUTS` ``preset``) to a cloud.

    ``captures``: one folder (a camera with the rig's projector; or, for a rig of two cameras and no projector,
    both cameras' files where the layout's names carry the camera, as OpenCV's do), two folders (camera 1's,
    camera 2's), globs or image files (one camera per glob or per folder of the files), or an image list file
    (OpenCV's ``pointcloud.cpp`` list); a folder without the tool's names is taken in numeric order of its images'
    names (:func:`rangekit.formats.layouts.capture_frames`). ``projector_size``: (width, height) of the tool's
    projector, needed when the rig has none. ``report`` gets one line per camera: which files, in which order.
    Returns a :class:`~rangekit.coded.reconstruct.Reconstruction` (camera and projector) or a
    :class:`~rangekit.stereo.coded_pair.PairReconstruction` (two cameras).
    """
    from rangekit.formats.capture import read_stack
    from rangekit.formats.layouts import LAYOUTS, arrange, capture_frames, decoding_projector
    from rangekit.stereo.coded_pair import reconstruct_pair

    layout = LAYOUTS[preset]
    width, height = _projector_size(rig, projector_size, preset)
    pair = rig.projector is None
    if pair and len(rig.cameras) < 2:
        raise ConfigError(f"{preset}: the rig has neither a projector nor a second camera; give a rig with a "
                          "projector (camera + projector) or with two cameras (matched through the projector's codes)")
    found = capture_frames(captures, layout, width, height, cameras=2 if pair else 1)
    where = found[0].source
    stacks, spec = [], None
    for frames in found:
        if report is not None:
            report(frames.line())
        stack, spec = arrange(list(read_stack(frames.files, what=f"a {preset} capture")), layout, width, height)
        stacks.append(stack)
    with naming(where):
        if pair:
            return reconstruct_pair(stacks, spec, rig.cameras[:2], subpixel=subpixel, **layout.view_options)
        projector = decoding_projector(rig.projector, layout)
        return reconstruct_view(stacks[0], spec, rig.camera, projector, subpixel=subpixel, method=method,
                                response=rig.projector_response, **layout.view_options)


def _projector_size(rig: Rig, given: tuple[int, int] | None, preset: str) -> tuple[int, int]:
    if rig.projector is None:
        if given is None:
            raise ConfigError(f"{preset}: the rig has no projector; give its size with --projector WxH (the size the "
                              "tool projected its patterns at)")
        return int(given[0]), int(given[1])
    size = rig.projector.width, rig.projector.height
    if given is not None and tuple(given) != size:
        raise ConfigError(f"--projector {given[0]}x{given[1]}: the rig's projector is {size[0]}x{size[1]}")
    return size
