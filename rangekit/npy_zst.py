"""Frames as zstd-compressed NumPy files, ``000.npy.zst``: a session's faster lossless frame format.

The file is Zstandard data (RFC 8878) whose content is an ``.npy`` file (NumPy's format 1.0: magic, a header
with ``descr``, ``fortran_order`` and ``shape``, then the pixels in C order), so standard tools open it:
``zstd -d 000.npy.zst`` gives ``000.npy`` for ``numpy.load``. It is two zstd frames, the ``.npy`` header in the
first (a few dozen bytes) and the pixels in the second, so that a reader knows an image's size from the
file's first bytes without decompressing the pixels (:func:`npy_zst_header`: the memory budget is checked
before any pixel is read, as for a PNG's IHDR chunk). Pixels are kept as the
camera gave them: (H, W) grey or (H, W, 3) RGB, uint8 or uint16.

Why: on the default 12-view session (720 frames of 1280x1024, 8-bit) a PNG takes about 7 ms to inflate and
20 ms to write at OpenCV's fastest level, this format about 2 ms and 5 ms (zstd level 3), for 2% more bytes
(``benchmarks/formats/bench_frame_formats.py SESSION``: 0.31x the reading time, 0.25x the writing time). Readers know the file by its first bytes (the zstd magic), as
OpenCV knows a PNG, not by its name.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from rangekit.errors import FileFormatError

__all__ = ["ZSTD_MAGIC", "NPY_ZST_SUFFIX", "LEVEL", "encode_npy_zst", "npy_zst_header", "decode_npy_zst",
           "is_npy_zst"]

ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
NPY_ZST_SUFFIX = ".npy.zst"
#: zstd's level: 3 (its default) wrote 4x faster than PNG's fastest level, for as many bytes; 6 saves 6% of
#: the bytes for 3x the writing time.
LEVEL = 3
_DTYPES = (np.dtype(np.uint8), np.dtype(np.uint16))


def is_npy_zst(data: bytes) -> bool:
    """Whether a file's first bytes are a zstd frame's (this module's format, or another zstd file)."""
    return data[:4] == ZSTD_MAGIC


def encode_npy_zst(image: np.ndarray, *, where: str | Path = "image") -> bytes:
    """The bytes of ``image`` ((H, W) or (H, W, 3) uint8/uint16, C order) as a ``.npy.zst`` file."""
    import zstandard

    img = np.asarray(image)
    if img.dtype not in _DTYPES or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise FileFormatError(f"{where}: a frame file needs an (H, W) or (H, W, 3) uint8/uint16 image, found "
                              f"{img.dtype} {img.shape}")
    img = np.ascontiguousarray(img)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, np.lib.format.header_data_from_array_1_0(img))
    c = zstandard.ZstdCompressor(level=LEVEL, write_content_size=True)
    return c.compress(buf.getvalue()) + c.compress(img.data)


def _parse_header(head: bytes, where: str | Path) -> tuple[tuple[int, ...], np.dtype, int]:
    """``(shape, dtype, offset of the pixels)`` from the first decompressed bytes; FileFormatError otherwise."""
    f = io.BytesIO(head)
    try:
        version = np.lib.format.read_magic(f)
        shape, fortran, dtype = (np.lib.format.read_array_header_1_0(f) if version == (1, 0)
                                 else np.lib.format.read_array_header_2_0(f))
    except (ValueError, EOFError, SyntaxError) as exc:
        raise FileFormatError(f"{where}: a zstd file whose content is not a NumPy .npy image header ({exc}); "
                              f"expected a {NPY_ZST_SUFFIX} frame") from None
    ok = (dtype in _DTYPES and not fortran and len(shape) in (2, 3) and all(s > 0 for s in shape)
          and (len(shape) == 2 or shape[2] == 3))
    if not ok:
        raise FileFormatError(f"{where}: frame holds a {'Fortran-order ' if fortran else ''}{dtype} array of shape "
                              f"{shape}; expected (H, W) or (H, W, 3), uint8 or uint16, C order")
    return tuple(int(s) for s in shape), dtype, f.tell()


def _header_frame(data: bytes, where: str | Path):
    """The first zstd frame decompressed (the .npy header), and the rest of the data (the pixels' frame)."""
    import zstandard

    try:
        d = zstandard.ZstdDecompressor().decompressobj()
        head = d.decompress(data)
        return head, d.unused_data
    except zstandard.ZstdError as exc:
        raise FileFormatError(f"{where}: damaged zstd data ({exc}); expected a {NPY_ZST_SUFFIX} frame") from None


def npy_zst_header(data: bytes, where: str | Path) -> tuple[tuple[int, ...], np.dtype]:
    """``(shape, dtype)`` of a ``.npy.zst`` file from its first bytes (``data``: a few hundred bytes or more),
    decompressing only the header's frame. FileFormatError naming ``where`` when it is not one."""
    head, _ = _header_frame(data, where)
    return _parse_header(head, where)[:2]


def decode_npy_zst(data: bytes, where: str | Path, *, out: np.ndarray | None = None) -> np.ndarray:
    """The image of a ``.npy.zst`` file's bytes: a new, writable (H, W) or (H, W, 3) array, or ``out`` filled with
    it (``out``: a writable C-contiguous array of the header's shape and dtype, e.g. one frame of a stack; the
    pixels are copied once, from zstd's buffer into it). FileFormatError naming ``where`` when the data is damaged,
    cut short, longer than its header says, not an image, or not ``out``'s shape and dtype."""
    import zstandard

    head, rest = _header_frame(data, where)
    shape, dtype, offset = _parse_header(head, where)
    if out is not None and (out.shape != shape or out.dtype != dtype):
        raise FileFormatError(f"{where}: frame holds a {dtype} {shape} image; expected {out.dtype} {out.shape}")
    size = int(np.prod(shape)) * dtype.itemsize
    pixels = None
    try:   # rangekit's files: the pixels alone in the second frame, whose header says their size: one call
        if len(head) == offset and zstandard.frame_content_size(rest) == size:
            pixels, complete, extra = zstandard.ZstdDecompressor().decompress(rest, allow_extra_data=False), True, b""
    except zstandard.ZstdError:   # cut short, bytes after the frame, damaged: as a stream, which says which
        pixels = None
    if pixels is None:
        pixels, complete, extra = _streamed(head[offset:], rest, where)
    if len(pixels) != size or not complete or extra:
        raise FileFormatError(f"{where}: frame holds {len(pixels):,} bytes of pixels{'' if complete else ', cut short'}"
                              f"{f' and {len(extra):,} bytes after them' if extra else ''}; its header says {size:,} "
                              f"({dtype} {shape}); the file is cut short or damaged")
    image = np.frombuffer(pixels, dtype=dtype).reshape(shape)
    if out is None:
        return image.copy()   # writable, like OpenCV's images
    out[...] = image
    return out


def _streamed(start: bytes, rest: bytes, where: str | Path) -> tuple[bytes, bool, bytes]:
    """``(pixels, complete, extra bytes)``: ``rest`` decompressed as a stream (no content size needed) after the
    header frame's own pixel bytes ``start``."""
    import zstandard

    try:
        d = zstandard.ZstdDecompressor().decompressobj()
        pixels = start + d.decompress(rest) if start else d.decompress(rest)
        return pixels, d.eof, d.unused_data
    except zstandard.ZstdError as exc:
        raise FileFormatError(f"{where}: damaged zstd data ({exc}); expected a {NPY_ZST_SUFFIX} frame") from None
