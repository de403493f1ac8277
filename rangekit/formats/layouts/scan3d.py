"""Moreno and Taubin's scan3d-capture folders ("Simple, accurate, and robust projector-camera calibration",
3DIMPVT 2012; ``src/ProjectorWidget.cpp`` makes the frames, ``src/CaptureDialog.cpp`` names the files,
``src/structured_light.cpp`` decodes them).

- ``scan3d:graycode``: ``cam_01.png ... cam_NN.png``: 01 white, 02 black, then P bits of the columns, then P
  of the rows, each from the most significant, the bit's frame then its inverse: ``N = 2 + 4 P``. Both axes
  code P bits, the code centred on the screen: a column ``u`` shows ``gray(u + o)``, ``o = (2**P - width) // 2``
  (rows alike). A bit is 1 where the frame is brighter than its inverse.
- The projector size is the one in the folder's ``projector_info.txt`` (the "effective" resolution
  scan3d-capture calibrates in, and writes into its calibration), and ``P`` the bits it needs,
  ``max(ceil(log2(width)), ceil(log2(height)))``.
"""

from __future__ import annotations

from rangekit.coded.patterns import PatternSpec, n_bits_for
from rangekit.formats.layouts.layout import AxisBlocks, CaptureLayout

__all__ = ["SCAN3D_LAYOUTS"]


def _bits(width: int, height: int) -> int:
    return max(n_bits_for(width), n_bits_for(height))


def _blocks(width: int, height: int) -> tuple[AxisBlocks, AxisBlocks]:
    p = _bits(width, height)
    return AxisBlocks(1, (2 ** p - width) // 2), AxisBlocks(1, (2 ** p - height) // 2)


def _spec(width: int, height: int) -> PatternSpec:
    """For the coded projector (``width`` + column offset, ``height`` + row offset): P bits on each axis."""
    return PatternSpec("graycode", width, height)


SCAN3D_LAYOUTS = {
    "scan3d:graycode": CaptureLayout(
        "scan3d:graycode", "scan3d-capture src/ProjectorWidget.cpp, CaptureDialog.cpp, structured_light.cpp",
        "cam_{:02d}.png", lambda w, h: 2 + 4 * _bits(w, h), _spec,
        lambda w, h: tuple(range(2 + 4 * _bits(w, h))), first_index=1, blocks=_blocks),
}
