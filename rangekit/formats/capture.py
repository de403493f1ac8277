"""Capture folders on disk: image lists in natural order, parallel loading, and the folder's metadata.

A capture folder (written by ``rangekit sim render`` or by acquisition) holds the raw images
(``000.png ...``), ``patterns.json`` (the PatternSpec), and usually ``rig.json`` and ``capture.json``.
"""

from __future__ import annotations

import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from rangekit._runtime.executor import worker_count
from rangekit.coded.patterns import PATTERN_METHODS, PatternSpec, make_pattern_spec
from rangekit.errors import ConfigError, FileFormatError, UsageError
from rangekit.image_header import check_image_files
from rangekit.io import atomic_save_npz, decode_image, read_json, read_png
from rangekit.npy_zst import decode_npy_zst, is_npy_zst, npy_zst_header
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.formats.sessions.files import PATTERNS_FILE, RIG_FILE

__all__ = ["IMAGE_SUFFIXES", "natural_key", "list_images", "read_stack", "stack_from_bytes", "Capture", "load_capture", "pattern_spec_for",
           "save_decoded"]

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".zst")   # .zst: NNN.npy.zst (rangekit.npy_zst)


def natural_key(path: Path):
    """Sort key of a file name in natural numeric order: runs of digits compared as numbers (``2.png`` before
    ``10.png``, ``01`` level with ``1``), the rest case-blind, as Qt's QCollator in numeric mode (SLStudio)."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", Path(path).name)]


def list_images(source: str | Path | Sequence[str | Path]) -> list[Path]:
    """Image files of a folder in natural numeric order (``2.png`` before ``10.png``), or the given list."""
    if isinstance(source, (str, Path)) and Path(source).is_dir():
        files = [p for p in Path(source).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES
                 and not p.name.startswith(".") and p.stem != "preview"]
        if not files:
            raise FileFormatError(f"{source}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
        return sorted(files, key=natural_key)
    paths = [Path(source)] if isinstance(source, (str, Path)) else [Path(p) for p in source]
    for p in paths:
        if not p.is_file():
            raise FileFormatError(f"{p}: no such image file")
    return paths


def read_stack(paths: Sequence[Path], *, workers: int = 0, what: str = "a capture") -> np.ndarray:
    """Read images (lossless, own bit depth, RGB order) on ``workers`` threads into one (K, H, W) or
    (K, H, W, 3) array; sizes must agree.

    The headers are read first (:func:`rangekit.image_header.check_image_files`): images of different sizes or
    depths, or a stack over the memory budget (:mod:`rangekit.budget`), are refused before any pixel is read.
    Each image is copied into the stack as it is read and its own buffer freed, so the next image reuses those
    pages: no list of images and no second, stacked copy (every fresh page is a page fault: ``/usr/bin/time -v
    rangekit decode ...`` counted about 75k through a list and ``np.stack``, 37k this way, for 46 images of
    2048x1500). A frame kept beyond the stack's life should be copied out of it.
    """
    check_image_files(paths, what=what)
    if len(paths) == 0:
        return np.zeros((0, 0, 0), dtype=np.uint8)
    first = read_png(paths[0])
    stack = np.empty((len(paths),) + first.shape, dtype=first.dtype)
    stack[0] = first
    del first

    def load(k: int) -> None:
        img = read_png(paths[k])
        if img.shape != stack.shape[1:] or img.dtype != stack.dtype:
            raise FileFormatError(f"{paths[k]}: image is {img.dtype} {img.shape}, but {Path(paths[0]).name} is "
                                  f"{stack.dtype} {stack.shape[1:]}; {what} needs one size and depth")
        stack[k] = img

    with ThreadPoolExecutor(max_workers=worker_count(workers)) as pool:
        for _ in pool.map(load, range(1, len(paths))):
            pass
    return stack


def stack_from_bytes(paths: Sequence[Path], contents: list[bytes], *, workers: int = 0,
                     what: str = "a capture", empty=np.empty) -> np.ndarray:
    """:func:`read_stack` of files already read: ``contents[k]`` the bytes of ``paths[k]`` (which name them in
    errors; no file is opened). The headers are checked first, then each image decoded into the stack on
    ``workers`` threads and its bytes dropped from ``contents``. ``empty(shape, dtype)`` makes the stack (e.g.
    :func:`rangekit._runtime.memory.reused_array`'s kept one: every pixel is written)."""
    check_image_files(paths, what=what, contents=contents)
    if len(paths) == 0:
        return np.zeros((0, 0, 0), dtype=np.uint8)
    if is_npy_zst(contents[0]):
        shape, dtype = npy_zst_header(contents[0], paths[0])
    else:
        first = decode_image(contents[0], paths[0])
        shape, dtype = first.shape, first.dtype
    stack = empty((len(paths),) + tuple(shape), dtype)
    if is_npy_zst(contents[0]):
        decode_npy_zst(contents[0], paths[0], out=stack[0])
    else:
        stack[0] = first
        del first

    def load(k: int) -> None:
        data, contents[k] = contents[k], b""
        if is_npy_zst(data) and npy_zst_header(data, paths[k]) == (stack.shape[1:], stack.dtype):
            decode_npy_zst(data, paths[k], out=stack[k])   # straight into the stack: one copy fewer a frame
            return
        img = decode_image(data, paths[k])
        if img.shape != stack.shape[1:] or img.dtype != stack.dtype:
            raise FileFormatError(f"{paths[k]}: image is {img.dtype} {img.shape}, but {Path(paths[0]).name} is "
                                  f"{stack.dtype} {stack.shape[1:]}; {what} needs one size and depth")
        stack[k] = img

    contents[0] = b""
    with ThreadPoolExecutor(max_workers=worker_count(workers)) as pool:
        for _ in pool.map(load, range(1, len(paths))):
            pass
    return stack


@dataclass(frozen=True, eq=False)
class Capture:
    """A capture folder's images and metadata."""

    folder: Path
    images: np.ndarray      # (K, H, W) or (K, H, W, 3), as read_stack reads them
    spec: PatternSpec | None
    rig: Rig | None
    info: dict

    @property
    def full_scale(self) -> float | None:
        """The camera's largest pixel value, ``2**bits - 1``: the simulator's imaging bits in
        ``capture.json``, else the rig file's ``capture.bits``; None: the images' dtype gives it."""
        return capture_full_scale(self.info, self.rig)


def capture_full_scale(info: dict, rig: Rig | None) -> float | None:
    """``2**bits - 1`` of a capture folder's camera: the simulator's imaging bits in ``capture.json`` (``info``),
    else the rig file's ``capture.bits``; None when neither says (the images' dtype gives it)."""
    imaging = info.get("imaging") if isinstance(info, dict) else None
    bits = (imaging.get("bits") if isinstance(imaging, dict) else None) \
        or (rig.capture.get("bits") if rig is not None else None)
    return float((1 << bits) - 1) if isinstance(bits, int) and 0 < bits <= 32 else None


def load_capture(folder: str | Path, *, workers: int = 0) -> Capture:
    """Read a capture folder; ``spec``/``rig`` are None when patterns.json / rig.json are absent."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder; expected a capture folder with 000.png ... and "
                              f"{PATTERNS_FILE}")
    spec = None
    if (folder / PATTERNS_FILE).exists():
        spec = PatternSpec.from_dict(read_json(folder / PATTERNS_FILE, what="pattern spec"),
                                     where=str(folder / PATTERNS_FILE))
    rig = load_rig(folder / RIG_FILE) if (folder / RIG_FILE).exists() else None
    info = read_json(folder / "capture.json", what="capture info") if (folder / "capture.json").exists() else {}
    return Capture(folder, read_stack(list_images(folder), workers=workers), spec, rig, info)


def pattern_spec_for(pattern: str, projector: tuple[int, int] | None) -> PatternSpec:
    """The spec of a pattern method name on a ``projector`` of (width, height) pixels, or read from a
    ``patterns.json`` file (whose size must then agree with ``projector`` when given)."""
    if pattern in PATTERN_METHODS:
        if projector is None:
            raise UsageError(f"--pattern {pattern} needs --projector WxH (the projector's resolution)")
        return make_pattern_spec(pattern, projector)
    spec = PatternSpec.from_dict(read_json(pattern, what="pattern spec"), where=pattern)
    if projector is not None and tuple(projector) != (spec.width, spec.height):
        raise ConfigError(f"{pattern} is for a {spec.width}x{spec.height} projector, --projector says "
                          f"{projector[0]}x{projector[1]}")
    return spec


#: The extension of :func:`save_decoded`'s file.
DECODED_SUFFIXES = (".npz",)


def save_decoded(path: str | Path, decoded, *, compress: bool = False) -> None:
    """Write a :class:`rangekit.coded.decode.DecodeResult`'s maps to ``path`` (.npz, atomically):
    proj_col, proj_row, confidence and the masks shadow, low_contrast, global_dominated, inconsistent (and motion,
    where the capture was checked for it: rangekit.coded.motion). Stored
    as ``np.savez`` does (16 bytes a pixel: 49 MB at 2048x1500, written in 0.08 CPU-s), or with ``compress``
    deflated at level 1 (7.6 MB, 0.27 CPU-s; numpy's level 6 gives 7.2 MB for 0.55 CPU-s)."""
    atomic_save_npz(path, level=1 if compress else 0, proj_col=decoded.proj_col, proj_row=decoded.proj_row,
                    confidence=decoded.confidence, shadow=decoded.shadow, low_contrast=decoded.low_contrast,
                    global_dominated=decoded.global_dominated, inconsistent=decoded.inconsistent,
                    **({} if getattr(decoded, "motion", None) is None else {"motion": decoded.motion}))
