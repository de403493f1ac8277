"""The calibration board found in a live frame, fast enough for the stream (a few milliseconds at 1280x1024): the
corners the Calibrate page draws over the picture while the board is placed.

A checkerboard is looked for in the frame scaled to at most :data:`LIVE_WIDTH` pixels wide with OpenCV's quick
check (``CALIB_CB_FAST_CHECK``, which gives up at once on a frame without a board), and its corners are scaled
back: a guide for the eye, not the subpixel corners the calibration measures (those come from
:func:`rangekit.boards.detect_board` on the captured pose). A ChArUco board goes through
:func:`~rangekit.boards.detect_board` itself, whose marker detection is already quick.
"""

from __future__ import annotations

import cv2
import numpy as np

from rangekit.boards import Board, detect_board
from rangekit.image import to_grey

__all__ = ["LIVE_WIDTH", "live_corners"]

#: Frames are searched at most this wide.
LIVE_WIDTH = 640


def live_corners(image: np.ndarray, board: Board) -> np.ndarray:
    """(n, 2) float camera pixels of ``board``'s inner corners found in ``image`` ((H, W) or (H, W, 3), any
    depth); (0, 2) when the board is not found whole."""
    img = np.asarray(image)
    grey = to_grey(img) if img.ndim == 3 else img
    if board.kind != "checkerboard":
        det = detect_board(grey, board)
        return np.asarray(det.uv, np.float64).reshape(-1, 2) if det.found else np.zeros((0, 2))
    if grey.dtype != np.uint8:
        grey = cv2.convertScaleAbs(grey, alpha=255.0 / max(1.0, float(grey.max())))
    scale = min(1.0, LIVE_WIDTH / grey.shape[1])
    small = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1.0 else grey
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(small, (board.cols - 1, board.rows - 1), flags=flags)
    if not found:
        return np.zeros((0, 2))
    return (corners.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5
