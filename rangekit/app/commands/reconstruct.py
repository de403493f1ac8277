"""One coded-light capture to a cloud (``rangekit reconstruct`` and ``rk.reconstruct``): the images, the rig and
the pattern set from a capture folder, or given, decoded and triangulated by
:func:`rangekit.coded.reconstruct.reconstruct_view`."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.coded.reconstruct import Reconstruction, reconstruct_view
from rangekit.errors import ConfigError, InputError, naming
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.surface.cloud import PointCloud

__all__ = ["reconstruct", "reconstruct_capture"]


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
