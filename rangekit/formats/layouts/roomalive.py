"""RoomAlive Toolkit's Gray-code captures (github microsoft/RoomAliveToolkit, ``ProCamCalibration/
ProCamEnsembleCalibration``: ``GrayCode.cs`` the patterns and the decoder, ``Calibrate.cs`` the capture and the
files).

- ``roomalive:graycode``: ``projectorP/cameraC/grayCode0.tiff ...``, numbered from 0 without padding, 8-bit grey
  (the Y channel of the Kinect v2's YUY2 colour frame, 1920 x 1080). For a W x H projector ``ceil(log2 W)``
  column bits then ``ceil(log2 H)`` row bits, each from the most significant, the bit's frame then its inverse:
  ``2 (11 + 11) = 44`` files for 1400 x 1050. The pattern lights a column (row) where bit b of its reflected
  Gray code ``x ^ (x >> 1)`` is 1. No white or black frame.
- RoomAlive's decoder (``GrayCode.Decode``): a bit is 1 where the frame is **at least** its inverse (``>=``: the
  decode option ``ties="one"``; rangekit's own rule is ``>``, and on this capture 56% of RoomAlive's masked pixels
  hold a tie in some bit); the code is the Gray code of the bits; a pixel is masked where ``|frame - inverse| <=
  10`` in any of the ``bits - 4`` most significant pairs of either axis (the 4 finest are decoded, not checked),
  or where its column is ``>= W`` or its row ``>= H``, one mask for both axes. The layout makes white and black
  from those pairs (:data:`~.layout.WHITE_FROM_PAIRS`: ``white - black`` is the smallest of their contrasts) and
  the decoder's shadow threshold is 10.5 levels, so that ``white - black < 10.5`` is RoomAlive's rule exactly;
  no direct/global separation (RoomAlive has none). Decoded with ``subpixel=False`` these are RoomAlive's
  ``decodedColumns.tiff``, ``decodedRows.tiff`` and ``mask.tiff``, pixel for pixel (flipped: below).
- The Kinect's frames are mirror images (flipped left to right by its SDK); ``mirror`` flips them back, so the
  maps are those of the camera the imported rig describes (:mod:`rangekit.formats.rig_files.roomalive`):
  ``numpy.fliplr`` of RoomAlive's.
"""

from __future__ import annotations

from rangekit.coded.patterns import PatternSpec, n_bits_for
from rangekit.formats.layouts.layout import BLACK_FROM_PAIRS, WHITE_FROM_PAIRS, CaptureLayout

__all__ = ["ROOMALIVE_LAYOUTS", "RA_THRESHOLD", "RA_UNCHECKED_BITS"]

#: ``GrayCode.Decode``: a pair is valid where ``|frame - inverse| > 10`` (8-bit levels) ...
RA_THRESHOLD = 10
#: ... checked on every bit but the 4 least significant of each axis.
RA_UNCHECKED_BITS = 4

#: RoomAlive's rule as rangekit's decode options: ties read 1; ``white - black`` (the smallest contrast of the
#: checked pairs) under 10.5 levels of 255 is shadow; no other test. Its room is 4.5 m away and the projector
#: 105 mm from the camera: 0.1 projector pixel is 9-29 mm there, and its calibration fits to 1.6 px (14 cm), so
#: the ray-ray and flying-pixel filters tuned for a desktop scanner (2 mm, 0.4%) drop every point: 50 mm, 3%.
VIEW_OPTIONS = {"decode_options": {"ties": "one", "shadow_threshold": (RA_THRESHOLD + 0.5) / 255,
                                   "min_contrast": (RA_THRESHOLD + 0.5) / 255, "max_global_ratio": float("inf")},
                "max_residual": 0.05, "max_jump": 0.03}


def _spec(width: int, height: int) -> PatternSpec:
    return PatternSpec("graycode", width, height)


def _files(width: int, height: int) -> dict:
    """The file index of each of the spec's binary frames."""
    files, k = {}, 0
    for prefix, n in (("col", n_bits_for(width)), ("row", n_bits_for(height))):
        for b in range(n - 1, -1, -1):
            files[f"{prefix}_b{b}"], files[f"{prefix}_b{b}_inv"] = k, k + 1
            k += 2
    return files


def _frames(width: int, height: int) -> tuple:
    files = {**_files(width, height), "white": WHITE_FROM_PAIRS, "black": BLACK_FROM_PAIRS}
    return tuple(files[name] for name in _spec(width, height).frame_names)


def _checked_pairs(width: int, height: int) -> tuple:
    """The (frame, inverse) files whose contrast RoomAlive's mask checks: all but the 4 finest bits per axis."""
    files = _files(width, height)
    return tuple((files[f"{prefix}_b{b}"], files[f"{prefix}_b{b}_inv"])
                 for prefix, n in (("col", n_bits_for(width)), ("row", n_bits_for(height)))
                 for b in range(n - 1, RA_UNCHECKED_BITS - 1, -1))


ROOMALIVE_LAYOUTS = {
    "roomalive:graycode": CaptureLayout(
        "roomalive:graycode", "RoomAliveToolkit ProCamCalibration/ProCamEnsembleCalibration/GrayCode.cs, Calibrate.cs",
        "grayCode{index}.tiff", lambda w, h: 2 * (n_bits_for(w) + n_bits_for(h)), _spec, _frames,
        view_options=VIEW_OPTIONS, pairs_for_references=_checked_pairs, mirror=True),
}
