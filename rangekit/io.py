"""Small file helpers: atomic writes and lossless image I/O (RGB in memory, BGR only inside OpenCV)."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import BinaryIO, Callable

import cv2
import numpy as np

from rangekit.errors import FileFormatError
from rangekit.image_header import check_image_files
from rangekit.npy_zst import NPY_ZST_SUFFIX, decode_npy_zst, encode_npy_zst, is_npy_zst
from rangekit.regular_files import read_regular_file

__all__ = ["atomic_write_bytes", "atomic_write_with", "fsync_folder", "atomic_write_text", "atomic_write_json", "encode_png", "write_png", "write_frame",
           "read_png", "decode_image",
           "atomic_save_npz", "atomic_save_npy", "read_json"]

# mkstemp creates 0600 files; give written files the usual mode (0666 minus the umask).
_UMASK = os.umask(0)
os.umask(_UMASK)
_FILE_MODE = 0o666 & ~_UMASK


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder and a rename (never half-written)."""
    atomic_write_with(path, lambda f: f.write(data))


def atomic_write_with(path: str | Path, write: Callable[[BinaryIO], object], *, sha256: bool = False) -> str | None:
    """``write(f)`` into a temporary file in ``path``'s folder (binary, seekable), then fsync and rename it to
    ``path``: never half-written. Writing straight into the file spares the copy through memory that
    building the bytes first costs (the 49 MB of maps ``rangekit decode`` stores: a fresh buffer's pages
    are faulted in and zeroed, then copied). ``sha256``: ``f`` hashes what is written (it is then not
    seekable: a zip is written as a stream) and the file's SHA-256 (hex) is returned, so a checksum never
    reads the file back; otherwise None."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    digest = None
    try:
        with os.fdopen(fd, "wb") as f:
            if sha256:
                digest = _Digesting(f)
                write(digest)
            else:
                write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except OSError as exc:  # a full disk, a file size limit, ...: name the file the user asked for
        Path(tmp).unlink(missing_ok=True)
        if exc.filename is None:
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    fsync_folder(path.parent)
    return None if digest is None else digest.hexdigest()


class _Digesting:
    """A write-only binary stream into ``f`` that takes the SHA-256 of what passes through it. It can tell its
    position but not seek, so a zip writer streams (data descriptors) instead of going back to the headers."""

    def __init__(self, f: BinaryIO) -> None:
        import hashlib

        self._f, self._sha256, self._n = f, hashlib.sha256(), 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        self._sha256.update(view)
        self._f.write(view)
        self._n += view.nbytes
        return view.nbytes

    def tell(self) -> int:
        return self._n

    def read(self, *_) -> bytes:   # numpy takes an object with ``read`` for a file; a zip being written never reads
        raise OSError("write-only stream")

    def flush(self) -> None:
        self._f.flush()

    def hexdigest(self) -> str:
        return self._sha256.hexdigest()


def fsync_folder(folder: str | Path) -> None:
    """Flush a folder's entries to disk, so that a rename in it survives a power cut (POSIX; a no-op where
    folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | Path, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=2) + "\n")


def read_json(path: str | Path, *, what: str = "JSON file") -> dict:
    """Read a JSON file; a missing or malformed file gives FileFormatError naming it."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise FileFormatError(f"{path}: {what} not found") from exc
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        # ValueError: not JSON, or an integer of more than 4300 digits; RecursionError: nesting too deep.
        raise FileFormatError(f"{path}: cannot read {what}: {str(exc)[:200]}") from exc


def atomic_save_npz(path: str | Path, *, level: int = 6, sha256: bool = False, **arrays: np.ndarray) -> str | None:
    """The arrays as an ``.npz`` (``np.load`` reads it) at ``path``, atomically. ``level``: zlib's deflate level,
    6 as ``np.savez_compressed``; 1 takes half its time for files about 5% larger (decoded maps); 0 stores
    them (``np.savez``: 7-20x faster than 6 for float maps, files 5-7x larger). ``sha256``: return the file's
    SHA-256 (:func:`atomic_write_with`)."""
    import zipfile

    def write(f) -> None:
        if level == 6:
            np.savez_compressed(f, **arrays)
        elif level == 0:
            np.savez(f, **arrays)
        else:
            with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=level) as zf:
                for name, arr in arrays.items():
                    with zf.open(name + ".npy", "w", force_zip64=True) as member:
                        np.lib.format.write_array(member, np.asanyarray(arr), allow_pickle=False)

    return atomic_write_with(path, write, sha256=sha256)


def atomic_save_npy(path: str | Path, array: np.ndarray) -> None:
    """``np.save`` to ``path``, atomically."""
    atomic_write_with(path, lambda f: np.save(f, np.asarray(array)))


#: The extension of :func:`write_png`'s files.
PNG_SUFFIXES = (".png",)


def write_png(path: str | Path, image: np.ndarray) -> bytes:
    """Write an (H, W) or (H, W, 3) RGB uint8/uint16 image as a lossless PNG, atomically; returns the
    file's bytes (for a checksum without reading the file back)."""
    data = encode_png(image, where=path)
    atomic_write_bytes(path, data)
    return data


def write_frame(path: str | Path, image: np.ndarray) -> bytes:
    """Write a captured frame, atomically, in the format its name says: ``NNN.npy.zst``
    (:mod:`rangekit.npy_zst`) or a PNG; returns the file's bytes (for its checksum)."""
    data = (encode_npy_zst(image, where=path) if str(path).endswith(NPY_ZST_SUFFIX)
            else encode_png(image, where=path))
    atomic_write_bytes(path, data)
    return data


def encode_png(image: np.ndarray, *, where: str | Path = "image") -> bytes:
    """An (H, W) or (H, W, 3) RGB uint8/uint16 image as the bytes of a lossless PNG (fast compression)."""
    path = where
    img = np.asarray(image)
    if img.dtype not in (np.uint8, np.uint16) or img.ndim not in (2, 3):
        raise FileFormatError(f"{path}: PNG needs an (H, W) or (H, W, 3) uint8/uint16 image, found "
                              f"{img.dtype} {img.shape}")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise FileFormatError(f"{path}: OpenCV could not encode the image as PNG")
    return buf.tobytes()


def read_png(path: str | Path) -> np.ndarray:
    """Read a PNG (or any lossless image OpenCV reads) unchanged in bit depth, colour as RGB.

    The file is read once (:func:`read_regular_file`: a regular file only, its path never handed to OpenCV)
    and its header checked (:func:`rangekit.image_header.check_image_files`) before the pixels are decoded:
    an image that would not fit the memory budget raises BudgetError first."""
    data = read_regular_file(path, what="an image")
    check_image_files([path], what="image", extra_bytes=0, contents=[data])
    return decode_image(data, path)


def decode_image(data: bytes, where: str | Path) -> np.ndarray:
    """:func:`read_png` of a file's bytes already read (``where`` names the file in errors); the caller has
    checked the header (:func:`rangekit.image_header.check_image_files` with ``contents``)."""
    if not data:
        raise FileFormatError(f"{where}: is empty (0 bytes); expected an image")
    if is_npy_zst(data):   # a session's faster frame format (rangekit.npy_zst)
        return decode_npy_zst(data, where)
    try:
        img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None:
        raise FileFormatError(f"{where}: not a readable image")
    return _as_rgb(img)


def _as_rgb(img: np.ndarray) -> np.ndarray:
    """An image as OpenCV reads it, colour as RGB (alpha dropped)."""
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return img
