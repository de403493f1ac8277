"""One coded-light capture to a cloud (``rangekit reconstruct`` and ``rk.reconstruct``): the images, the rig and
the pattern set from a capture folder, or given, decoded and triangulated by
:func:`rangekit.coded.reconstruct.reconstruct_view`; another tool's capture folder in its own layout
(:func:`reconstruct_tool_capture`), with a camera and a projector or with two cameras
(:func:`rangekit.stereo.coded_pair.reconstruct_pair`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import os

import numpy as np

from rangekit._runtime.arguments import check_bool, check_choice, check_path, check_text, refuse
from rangekit.app.process.options import TRIANGULATION_METHODS
from rangekit.coded.motion import MAX_MOTION_SHARE
from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.app.commands.rig_choice import Refined, RigChoice, choose_rig, refine_from_capture
from rangekit.coded.reconstruct import Reconstruction, decoded_coordinates, reconstruct_decoded, reconstruct_view
from rangekit.errors import ConfigError, FileFormatError, InputError, naming
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.stereo.coded_pair import PairReconstruction
from rangekit.surface.cloud import PointCloud
from rangekit.formats.sessions.files import PATTERNS_FILE, RIG_FILE

__all__ = ["CheckedReconstruction", "reconstruct", "reconstruct_capture", "reconstruct_checked", "reconstruct_tool_capture"]


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
    an unreadable image, PatternError when the images do not fit the pattern set; an argument of the wrong type or
    value is refused before anything is read (InputError naming it).
    """
    if isinstance(images_or_folder, (str, os.PathLike)):
        check_path("images_or_folder", images_or_folder, what="a capture folder")
        if not Path(images_or_folder).is_dir():
            refuse("images_or_folder", images_or_folder, "a capture folder (or a list of image files or arrays); "
                   "there is no such folder", error=FileFormatError)
    if not isinstance(rig, Rig):
        check_path("rig", rig, what="a Rig or a rig file", optional=True)
    if not isinstance(pattern, PatternSpec):
        check_text("pattern", pattern, what="a PatternSpec or a pattern method name", optional=True)
    check_choice("method", method, TRIANGULATION_METHODS)
    check_bool("subpixel", subpixel)
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
                          f"{', or put ' + RIG_FILE + ' in the folder' if folder_spec is not None or where != 'images' else ''})")
    if isinstance(pattern, str):
        pattern = make_pattern_spec(pattern, (rig.projector.width, rig.projector.height))
    spec = pattern if pattern is not None else folder_spec
    if spec is None:
        raise ConfigError(f"{where}: no pattern set; give pattern= (a PatternSpec or a method name) or put "
                          f"{PATTERNS_FILE} in the folder")
    with naming(where):
        return reconstruct_view(images, spec, rig.camera, rig.projector, subpixel=subpixel, method=method,
                                full_scale=full_scale, response=rig.projector_response, motion=True,
                                **(view_options or {}))


def reconstruct_checked(capture, rigs: Sequence[tuple[str, Rig]], *, subpixel: bool = True, method: str = "auto",
                        refine: bool = True, free_intrinsics: bool = False,
                        max_motion: float | None = MAX_MOTION_SHARE) -> CheckedReconstruction:
    """A rangekit capture folder (or one loaded) decoded once and reconstructed with the rig of ``rigs`` that fits
    it best, refined from it when it does not fit (:func:`reconstruct_tool_capture`'s rules)."""
    from rangekit.coded.decode import decode
    from rangekit.rig.capture_check import check_rig

    images, _, spec, full_scale, where = _images(capture)
    if spec is None:
        raise ConfigError(f"{where}: no {PATTERNS_FILE}; give the pattern set")
    with naming(where):
        dec = decode(images, spec, subpixel=subpixel, full_scale=full_scale, response=rigs[0][1].projector_response,
                     motion=True, max_motion=max_motion)
        cols, rows = decoded_coordinates(dec, 0.03)

        def check(r: Rig):
            if r.projector is None:
                raise ConfigError("it has no projector")
            if r.camera.size != (cols.shape[1], cols.shape[0]):
                raise ConfigError(f"the captures are {cols.shape[1]}x{cols.shape[0]} but the rig's camera "
                                  f"{r.camera.name!r} is {r.camera.width}x{r.camera.height}")
            if r.projector.size != (spec.width, spec.height):
                raise ConfigError(f"the pattern spec is for a {spec.width}x{spec.height} projector but the rig's "
                                  f"projector is {r.projector.width}x{r.projector.height}")
            return check_rig(r.camera, r.projector, cols, rows), False

        choice = choose_rig(rigs, check)
        refined = refine_from_capture(choice.rig.camera, choice.rig.projector, cols,
                                      rows if rows is not None else np.full_like(cols, np.nan), choice.check,
                                      refine=refine, free_intrinsics=free_intrinsics)
        rec = reconstruct_decoded(dec, choice.rig.camera, refined.second, method=method, full_scale=full_scale)
    return CheckedReconstruction(rec, choice, refined)


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


@dataclass(frozen=True, eq=False)
class CheckedReconstruction:
    """A capture reconstructed with the rig that fits it best among those given, refined from it when needed."""

    reconstruction: Reconstruction | PairReconstruction
    choice: RigChoice                   # which rig, how each fitted, the chosen one's check as given
    refined: Refined                    # the second device triangulated with, and the refinement's line

    def lines(self) -> list[str]:
        """What a person reads: the ranking (several rigs), the pairing (two cameras), the check, the refinement
        and the check after it."""
        rec = self.reconstruction
        out = self.choice.lines()
        if isinstance(rec, PairReconstruction):
            out.append(rec.pairing_line())
        out.append(self.choice.check.describe())
        if self.refined.line:
            out.append(self.refined.line)
        if self.refined.refinement is not None and rec.rig_check is not None:
            out.append("after refinement: " + rec.rig_check.describe())
        return out


def reconstruct_tool_capture(captures: Sequence[str | Path], preset: str, rig, *,
                             projector_size: tuple[int, int] | None = None, subpixel: bool = True,
                             method: str = "auto", report: Callable[[str], object] | None = None,
                             refine: bool = True, free_intrinsics: bool = False,
                             max_motion: float | None = MAX_MOTION_SHARE) -> CheckedReconstruction:
    """Another tool's capture as it lies on disk (:data:`rangekit.formats.layouts.LAYOUTS` ``preset``) to a cloud.

    ``captures``: one folder (a camera with the rig's projector; or, for a rig of two cameras and no projector,
    both cameras' files where the layout's names carry the camera, as OpenCV's do), two folders (camera 1's,
    camera 2's), globs or image files (one camera per glob or per folder of the files), or an image list file
    (OpenCV's ``pointcloud.cpp`` list); a folder without the tool's names is taken in numeric order of its images'
    names (:func:`rangekit.formats.layouts.capture_frames`). ``rig``: a :class:`Rig`, or (name, Rig) pairs to
    choose from by their fit to the capture (:func:`rangekit.app.commands.rig_choice.choose_rig`; all of one
    kind: camera and projector, or two cameras). ``projector_size``: (width, height) of the tool's projector,
    needed when the rig has none. ``report`` gets one line per camera: which files, in which order. ``refine``:
    the rig refined from the capture when it does not fit (``free_intrinsics``: the projector's or camera 2's
    focal lengths and principal point too). The reconstruction is a
    :class:`~rangekit.coded.reconstruct.Reconstruction` (camera and projector) or a
    :class:`~rangekit.stereo.coded_pair.PairReconstruction` (two cameras).
    """
    from rangekit.coded.decode import decode
    from rangekit.formats.capture import read_stack
    from rangekit.formats.layouts import LAYOUTS, arrange, capture_frames, decoding_projector
    from rangekit.rig.capture_check import check_pair, check_rig
    from rangekit.stereo.coded_pair import match_pair, pair_cameras, pairings, triangulate_pair

    rigs = [("rig", rig)] if isinstance(rig, Rig) else list(rig)
    layout = LAYOUTS[preset]
    first = rigs[0][1]
    width, height = _projector_size(first, projector_size, preset)
    pair = first.projector is None
    if pair and len(first.cameras) < 2:
        raise ConfigError(f"{preset}: the rig has neither a projector nor a second camera; give a rig with a "
                          "projector (camera + projector) or with two cameras (matched through the projector's codes)")
    if any((r.projector is None) != pair for _, r in rigs):
        raise ConfigError(f"--rig: {', '.join(n for n, _ in rigs)} mix camera-projector and two-camera rigs; give rigs "
                          "of one kind")
    found = capture_frames(captures, layout, width, height, cameras=2 if pair else 1)
    where = found[0].source
    stacks, spec = [], None
    for frames in found:
        if report is not None:
            report(frames.line())
        stack, spec = arrange(list(read_stack(frames.files, what=f"a {preset} capture")), layout, width, height)
        stacks.append(stack)
    options = dict(layout.view_options)
    decode_options = options.pop("decode_options", {})
    if pair:   # each camera's decoding named by its own folder (a dark camera 2 is camera 2's)
        match = match_pair(stacks, spec, subpixel=subpixel, sources=[frames.source for frames in found],
                           decode_options={**decode_options, "motion": True, "max_motion": max_motion},
                           **{k: v for k, v in options.items() if k == "min_confidence"})
    with naming(where):
        if pair:

            def check(r: Rig):
                options_ = pairings(r.cameras[:2], match.sizes)
                used, checked, exchanged = pair_cameras([p for p, _ in options_], match.x2, match.y2,
                                                        exchanged=[e for _, e in options_])
                return checked, exchanged

            choice = choose_rig(rigs, check)
            cams = choice.rig.cameras[:2][::-1] if choice.exchanged else choice.rig.cameras[:2]
            refined = refine_from_capture(cams[0], cams[1], match.x2, match.y2, choice.check, refine=refine,
                                          free_intrinsics=free_intrinsics, exchanged=choice.exchanged)
            used = (refined.second, cams[1]) if choice.exchanged else (cams[0], refined.second)
            rec = triangulate_pair(match, used, exchanged=choice.exchanged,
                                   **{k: v for k, v in options.items() if k != "min_confidence"})
            return CheckedReconstruction(rec, choice, refined)
        dec = decode(stacks[0], spec, subpixel=subpixel, response=first.projector_response, motion=True,
                     max_motion=max_motion, **decode_options)
        cols, rows = decoded_coordinates(dec, options.get("min_confidence", 0.03))

        def check(r: Rig):
            _same_size(r, (width, height))
            projector = decoding_projector(r.projector, layout)
            if r.camera.size != (cols.shape[1], cols.shape[0]):
                raise ConfigError(f"the captures are {cols.shape[1]}x{cols.shape[0]} but the rig's camera "
                                  f"{r.camera.name!r} is {r.camera.width}x{r.camera.height}")
            return check_rig(r.camera, projector, cols, rows), False

        choice = choose_rig(rigs, check)
        projector = decoding_projector(choice.rig.projector, layout)
        refined = refine_from_capture(choice.rig.camera, projector, cols,
                                      rows if rows is not None else np.full_like(cols, np.nan),
                                      choice.check, refine=refine, free_intrinsics=free_intrinsics)
        rec = reconstruct_decoded(dec, choice.rig.camera, refined.second, method=method, **options)
        return CheckedReconstruction(rec, choice, refined)


def _same_size(rig: Rig, size: tuple[int, int]) -> None:
    if (rig.projector.width, rig.projector.height) != tuple(size):
        raise ConfigError(f"its projector is {rig.projector.width}x{rig.projector.height}, the capture's frames are "
                          f"for {size[0]}x{size[1]}")


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
