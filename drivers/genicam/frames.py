"""A GenICam buffer's image as rangekit's frame: (H, W) grey or (H, W, 3) RGB, uint8 or uint16.

=====================================  =====================================================================
``Mono8``                              (H, W) uint8
``Mono10``, ``Mono12``, ``Mono16``     (H, W) uint16, values up to 2**bits - 1 (``capture.bits`` 10, 12, 16)
``Bayer{RG,GR,GB,BG}{8,10,12,16}``     demosaicked (OpenCV, edge-aware bilinear) and made grey by rangekit's one
                                       rule (:func:`rangekit.image.to_grey`, the mean of R, G, B): (H, W), the
                                       mosaic's dtype
``RGB8``, ``BGR8``, ``RGBa8``,         (H, W, 3) uint8 RGB (alpha dropped); grey (H, W) with ``white_balance_k``
``BGRa8``                              ``"mono"``
=====================================  =====================================================================

Packed formats (``Mono12p``, ``Mono10Packed``, ...) are not read: the section's ``pixel_format`` must be one of
:data:`PIXEL_FORMATS`, and the camera is set to it before it streams. GenICam names a Bayer mosaic by its top-left
2x2 block (``BayerRG``: red at (0, 0)); OpenCV names it by the block at (1, 1), so GenICam's ``BayerRG`` is OpenCV's
``BayerBG`` (tested on a red mosaic).
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import DeviceError
from rangekit.image import to_grey
from rangekit.rig.checks import GENICAM_PIXEL_FORMATS

__all__ = ["PIXEL_FORMATS", "MONO_FORMATS", "BAYER_FORMATS", "COLOUR_FORMATS", "frame_from_buffer", "to_frame"]

#: The pixel formats ``devices.camera.pixel_format`` takes (the rig file's check holds the list).
PIXEL_FORMATS = GENICAM_PIXEL_FORMATS
MONO_FORMATS = tuple(f for f in PIXEL_FORMATS if f.startswith("Mono"))
BAYER_FORMATS = tuple(f for f in PIXEL_FORMATS if f.startswith("Bayer"))
COLOUR_FORMATS = tuple(f for f in PIXEL_FORMATS if f not in MONO_FORMATS + BAYER_FORMATS)
#: GenICam's mosaic name -> OpenCV's (module docstring).
_OPENCV_BAYER = {"RG": "BG", "GR": "GB", "GB": "GR", "BG": "RG"}


def _bits(fmt: str) -> int:
    return int("".join(c for c in fmt if c.isdigit()) or 8)


def to_frame(data: np.ndarray, width: int, height: int, fmt: str, *, grey: bool = False) -> np.ndarray:
    """The frame of one buffer's pixels ``data`` (flat or shaped, as harvesters gives them) in pixel format
    ``fmt`` (module docstring); a copy, so the buffer can go back to the camera at once. ``grey``: colour made
    grey. DeviceError for a format not in :data:`PIXEL_FORMATS` or data of the wrong size."""
    import cv2

    if fmt not in PIXEL_FORMATS:
        raise DeviceError(f"pixel format {fmt!r} is not read by rangekit; use one of {', '.join(PIXEL_FORMATS)}")
    dtype = np.uint8 if _bits(fmt) == 8 else np.uint16
    channels = {"RGB8": 3, "BGR8": 3, "RGBa8": 4, "BGRa8": 4}.get(fmt, 1)
    a = np.asarray(data)
    if a.dtype != dtype:
        a = a.view(dtype) if a.dtype.itemsize != np.dtype(dtype).itemsize else a.astype(dtype)
    if a.size != width * height * channels:
        raise DeviceError(f"a {fmt} frame of {width}x{height} needs {width * height * channels} values, the buffer "
                          f"has {a.size}")
    a = a.reshape((height, width, channels) if channels > 1 else (height, width))
    if fmt in MONO_FORMATS:
        return a.copy()
    if fmt in BAYER_FORMATS:
        code = getattr(cv2, f"COLOR_Bayer{_OPENCV_BAYER[fmt[5:7]]}2RGB_EA")
        return _grey(cv2.cvtColor(np.ascontiguousarray(a), code), dtype)
    rgb = a[..., :3] if fmt.startswith("RGB") else a[..., 2::-1]
    return _grey(rgb, dtype) if grey else np.ascontiguousarray(rgb)


def _grey(rgb: np.ndarray, dtype) -> np.ndarray:
    """RGB made grey by :func:`rangekit.image.to_grey`, rounded back to ``dtype``."""
    return np.rint(to_grey(rgb)).astype(dtype)


def frame_from_buffer(buffer, *, grey: bool = False) -> tuple[np.ndarray, str]:
    """(frame, pixel format) of a harvesters ``Buffer``'s first image component."""
    components = buffer.payload.components
    if not components:
        raise DeviceError("the camera sent a buffer without an image")
    c = components[0]
    return to_frame(c.data, int(c.width), int(c.height), str(c.data_format), grey=grey), str(c.data_format)
