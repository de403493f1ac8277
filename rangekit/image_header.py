"""Image sizes from file headers, read before any pixel: so that a stack that would not fit the memory budget
(:mod:`rangekit.budget`) or whose images differ in size or depth is refused before it is loaded.

:func:`read_image_header` knows the formats rangekit reads (``rangekit.formats.capture.IMAGE_SUFFIXES``)
by their first bytes, not their names (OpenCV does the same): PNG (IHDR chunk), TIFF (first IFD, classic
and BigTIFF), BMP (DIB header) the netpbm PGM/PPM/PBM (text header) and a session's ``.npy.zst`` frames (:mod:`rangekit.npy_zst`). For anything else it returns None
and the image is checked only after OpenCV has read it.

``channels`` and ``bits`` describe the image as :func:`rangekit.io.read_png` returns it (alpha dropped;
palette and 1/2/4-bit images expanded to 8 bits), so ``nbytes`` is what the array will take (for a BMP,
whose palette decides between grey and colour, at most that).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from rangekit.budget import check_budget, format_bytes
from rangekit.errors import FileFormatError
from rangekit.npy_zst import is_npy_zst, npy_zst_header
from rangekit.regular_files import read_regular_file

__all__ = ["ImageHeader", "read_image_header", "check_image_files"]

_HEAD = 4096  # bytes read from each file: enough for every header above (TIFF: its first IFD, if early)


@dataclass(frozen=True)
class ImageHeader:
    """An image's size from its header: ``width`` x ``height`` pixels, ``channels`` (1 or 3) of ``bits``
    (8, 16 or 32) each, as :func:`rangekit.io.read_png` returns it; ``format``: "png", "tiff", "bmp", "pnm",
    "npy.zst"."""

    width: int
    height: int
    channels: int
    bits: int
    format: str
    file_bits: int = 0   # bits per sample in the file when fewer than ``bits`` (a 1-bit PNG read as 8-bit); 0: ``bits``

    @property
    def nbytes(self) -> int:
        """Bytes of the decoded array."""
        return self.width * self.height * self.channels * (self.bits // 8)

    def describe(self) -> str:
        stored = f" ({self.file_bits}-bit in the file)" if self.file_bits else ""
        return f"{self.width}x{self.height} {self.channels}-channel {self.bits}-bit{stored}"


def _depth(bits: int) -> int:
    """OpenCV's array depth for a sample of ``bits``: 1..8 -> 8, 9..16 -> 16, more -> 32."""
    return 8 if bits <= 8 else 16 if bits <= 16 else 32


def _png(b: bytes) -> tuple[int, int, int, int, int] | None:
    if len(b) < 8 + 8 + 13 or b[12:16] != b"IHDR":
        return None
    w, h, bits, colour = struct.unpack(">IIBB", b[16:26])
    channels = {0: 1, 2: 3, 3: 3, 4: 3, 6: 3}.get(colour)  # grey, RGB, palette, grey+alpha -> BGRA, RGBA
    return None if channels is None else (w, h, channels, _depth(bits), bits if bits < _depth(bits) else 0)


def _tiff(b: bytes, path: Path) -> tuple[int, int, int, int] | None:
    e = "<" if b[:2] == b"II" else ">"
    big = struct.unpack(e + "H", b[2:4])[0] == 43  # BigTIFF: 8-byte offsets and counts, 20-byte entries
    off = struct.unpack(e + ("Q" if big else "I"), b[8:16] if big else b[4:8])[0]
    count_fmt, entry, inline = ("Q", 20, 8) if big else ("H", 12, 4)
    tags = {}
    with open(path, "rb") as f:
        f.seek(off)
        raw = f.read(struct.calcsize(count_fmt))
        n = struct.unpack(e + count_fmt, raw)[0]
        entries = f.read(min(n, 4096) * entry)
        for k in range(len(entries) // entry):
            item = entries[k * entry: (k + 1) * entry]
            tag, typ = struct.unpack(e + "HH", item[:4])
            fmt = {1: "B", 3: "H", 4: "I", 16: "Q"}.get(typ)
            if fmt is None or tag not in (256, 257, 258, 277):
                continue
            count = struct.unpack(e + ("Q" if big else "I"), item[4:12] if big else item[4:8])[0]
            value = item[12:] if big else item[8:]
            if count * struct.calcsize(fmt) > inline:  # the values are elsewhere: read the first
                f.seek(struct.unpack(e + ("Q" if big else "I"), value)[0])
                value = f.read(struct.calcsize(fmt))
            tags[tag] = struct.unpack(e + fmt, value[:struct.calcsize(fmt)])[0]
    if 256 not in tags or 257 not in tags:
        return None
    return tags[256], tags[257], 1 if tags.get(277, 1) == 1 else 3, _depth(tags.get(258, 1))


def _bmp(b: bytes) -> tuple[int, int, int, int] | None:
    if len(b) < 30:
        return None
    size = struct.unpack("<I", b[14:18])[0]
    if size == 12:
        w, h = struct.unpack("<HH", b[18:22])
    else:
        w, h = struct.unpack("<ii", b[18:26])
    return abs(w), abs(h), 3, 8  # OpenCV reads every BMP as 8-bit BGR(A) or grey; 3 channels bounds it


def _pnm(b: bytes) -> tuple[int, int, int, int] | None:
    text = b"\n".join(line.split(b"#", 1)[0] for line in b[2:].split(b"\n"))
    tokens = text.split()
    need = 2 if b[1:2] in b"14" else 3
    if len(tokens) < need or not all(t.isdigit() for t in tokens[:need]):
        return None
    w, h = int(tokens[0]), int(tokens[1])
    maxval = 1 if need == 2 else int(tokens[2])
    return w, h, 3 if b[1:2] in b"36" else 1, 16 if maxval > 255 else 8


def read_image_header(path: str | Path, data: bytes | None = None) -> ImageHeader | None:
    """The size of the image in ``path`` from its first bytes (``data``: the file's bytes, already read), or
    None for a format not known here.

    Raises FileFormatError when the file cannot be opened, or when it has a known signature but a header
    that is cut short or holds a zero size.
    """
    path = Path(path)
    if data is not None:
        b = data
    else:
        b = read_regular_file(path, what="an image file", limit=_HEAD)
    if b[:8] == b"\x89PNG\r\n\x1a\n":
        kind, parse = "png", _png
    elif b[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        kind, parse = "tiff", lambda head: _tiff(head, path)
    elif b[:2] == b"BM":
        kind, parse = "bmp", _bmp
    elif len(b) > 2 and b[:1] == b"P" and b[1:2] in b"123456" and b[2:3].isspace():
        kind, parse = "pnm", _pnm
    elif is_npy_zst(b):    # a session's NNN.npy.zst frame: its header in the first zstd frame
        shape, dtype = npy_zst_header(b, path)
        return ImageHeader(shape[1], shape[0], 1 if len(shape) == 2 else 3, 8 * dtype.itemsize, "npy.zst")
    else:
        return None
    try:
        found = parse(b)
    except (struct.error, OSError, ValueError):
        found = None
    if found is None or found[0] < 1 or found[1] < 1:
        raise FileFormatError(f"{path}: not a readable {kind.upper()} image: its header is cut short, damaged or "
                              f"gives a zero size ({'x'.join(map(str, found[:2])) if found else 'no size'})")
    return ImageHeader(*found[:4], kind, file_bits=found[4] if len(found) > 4 else 0)


def check_image_files(paths: Sequence[str | Path], *, what: str = "image stack", same_size: bool = True,
                      copies: int = 1, bytes_per_pixel: int | None = None,
                      extra_bytes: int | None = None, contents: Sequence[bytes] | None = None) -> list[ImageHeader | None]:
    """Read the headers of ``paths`` and refuse, before any pixel is read, images that differ in size or depth
    (FileFormatError naming the first file that differs, when ``same_size``) or a set that would not fit the
    memory budget (BudgetError): ``copies`` of every image (2 when the caller stacks them into one array) at
    ``bytes_per_pixel`` (default: as read, ``ImageHeader.nbytes``; e.g. 4 when the caller keeps float32 grey)
    plus ``extra_bytes`` (default: two of the largest image as read, the reader's working copies). Returns the
    headers (None for formats without a known header: those are checked after reading only). ``contents``: the
    files' bytes, already read (then no file is opened)."""
    headers = [read_image_header(p, None if contents is None else contents[k]) for k, p in enumerate(paths)]
    known = [(Path(p), h) for p, h in zip(paths, headers) if h is not None]
    if not known:
        return headers
    p0, h0 = known[0]
    if same_size:
        for p, h in known[1:]:
            if (h.width, h.height, h.bits, h.file_bits) != (h0.width, h0.height, h0.bits, h0.file_bits):
                raise FileFormatError(f"{p}: image is {h.describe()}, but {p0.name} is {h0.describe()}; "
                                      f"{what} needs one size and depth (from the image headers)")
    largest = max(h.nbytes for _, h in known)
    kept = sum(h.nbytes if bytes_per_pixel is None else h.width * h.height * bytes_per_pixel for _, h in known)
    total = copies * kept + (2 * largest if extra_bytes is None else extra_bytes)
    where = p0 if len(paths) == 1 else p0.parent
    check_budget(total, f"{what} ({where}: {len(paths)} image(s) of {h0.describe()}, "
                        f"{format_bytes(h0.nbytes)} each)")
    return headers
