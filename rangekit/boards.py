"""Calibration boards (checkerboard and ChArUco): geometry, printable texture and detection.

Board frame (both kinds), metres: x along the columns of squares, y along the rows, z = 0 the board
plane. Inner corner id ``k = i * (cols - 1) + j`` is at ``(j * square, i * square, 0)``; the squares
span x in ``[-square, (cols - 1) * square]`` and y in ``[-square, (rows - 1) * square]``, and the square
at the (-x, -y) end is dark. The printed side faces **-z**: seen from the printed side, x runs to the
right and y downwards, exactly as in :meth:`Board.texture` (image row 0 at the smallest y) and in
OpenCV's board images. This is OpenCV's convention (a board posed by ``solvePnP`` has z pointing away
from the camera); with the printed side towards +z the viewer would see the pattern mirrored and the
ArUco markers of a ChArUco board could not be decoded.

For ChArUco boards the layout is OpenCV's ``cv2.aruco.CharucoBoard((cols, rows), ...)`` (OpenCV >= 4.6
pattern, not the legacy one) shifted by ``-square`` in x and y, so the corner ids are OpenCV's ChArUco ids
and its first (top-left) square, which OpenCV 5 always draws black, is our dark (-x, -y) square.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from rangekit.budget import check_budget
from rangekit._runtime.memory import forgettable_cache
from rangekit.errors import InputError
from rangekit.image import to_grey

__all__ = ["Board", "BoardDetection", "detect_board", "MAX_SQUARES"]

_KINDS = ("checkerboard", "charuco")
MAX_SQUARES = 100  # squares per side: a board is printed, detected and textured whole (texture(): the budget)


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True)
class Board:
    """A printed calibration board (see the module docstring for its frame).

    Attributes
    ----------
    kind : {"checkerboard", "charuco"}
    cols, rows : int
        Number of squares along board x and y (default 10 x 7, giving 9 x 6 = 54 inner corners). With
        ``rows + cols`` odd (the default) a checkerboard is not symmetric under a 180 degree turn, so its
        corner ids can be recovered from the image; :func:`detect_board` refuses checkerboards with
        ``rows + cols`` even. ChArUco boards are identified by their markers whatever the size.
    square : float
        Side of one square, metres.
    marker : float or None
        ChArUco marker side in metres (default ``0.75 * square``); ignored by checkerboards.
    dictionary : str
        OpenCV ArUco dictionary name for ChArUco markers, e.g. "DICT_5X5_100".
    margin : float
        Width of the light border around the squares, metres.
    dark, light : float
        Albedo of dark and light areas, ``0 <= dark < light <= 1``.
    """

    kind: str = "checkerboard"
    cols: int = 10
    rows: int = 7
    square: float = 0.02
    marker: float | None = None
    dictionary: str = "DICT_5X5_100"
    margin: float = 0.01
    dark: float = 0.05
    light: float = 0.9

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise InputError(f"Board: kind must be one of {_KINDS}, found {self.kind!r}")
        for name in ("cols", "rows"):
            value = getattr(self, name)
            if not _is_int(value) or not 2 <= value <= MAX_SQUARES:
                raise InputError(f"Board: {name} (squares) must be an integer in 2..{MAX_SQUARES}, found {value!r}")
            object.__setattr__(self, name, int(value))
        for name in ("square", "margin", "dark", "light"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not np.isfinite(value):
                raise InputError(f"Board: {name} must be a finite number, found {value!r}")
            object.__setattr__(self, name, float(value))
        if not self.square > 0:
            raise InputError(f"Board: square must be > 0 metres, found {self.square!r}")
        if not self.margin >= 0:
            raise InputError(f"Board: margin must be >= 0 metres, found {self.margin!r}")
        if not 0.0 <= self.dark < self.light <= 1.0:
            raise InputError(f"Board: need 0 <= dark < light <= 1 (albedo), found dark={self.dark!r}, "
                             f"light={self.light!r}")
        marker = 0.75 * self.square if self.marker is None else self.marker
        if not (isinstance(marker, (int, float, np.floating, np.integer)) and 0 < marker < self.square):
            raise InputError(f"Board: marker must be in (0, square={self.square}) metres, found {marker!r}")
        object.__setattr__(self, "marker", float(marker))
        if not (isinstance(self.dictionary, str) and self.dictionary.startswith("DICT_")
                and hasattr(cv2.aruco, self.dictionary)):
            raise InputError(f"Board: dictionary must name an OpenCV ArUco dictionary such as 'DICT_5X5_100', "
                             f"found {self.dictionary!r}")
        if self.kind == "charuco":
            n_markers = self.cols * self.rows // 2
            size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
            if n_markers > size:
                raise InputError(f"Board: a {self.cols}x{self.rows} ChArUco board needs {n_markers} markers but "
                                 f"dictionary {self.dictionary} has {size}; use a larger dictionary, e.g. "
                                 f"'DICT_5X5_{250 if n_markers <= 250 else 1000}'")

    # ---------------------------------------------------------------- geometry
    def transposed(self) -> "Board":
        """The same print read the other way round: ``cols`` and ``rows`` exchanged, so board x and y are too.

        A checkerboard with ``cols`` or ``rows`` odd is found under either reading (its dark corner square is
        where the other reading needs it, a quarter turn away); one with both even only under the print's own,
        which :func:`rangekit.calib.recorded.board_readings` tries in turn."""
        return dataclasses.replace(self, cols=self.rows, rows=self.cols)

    @property
    def n_corners(self) -> int:
        """Number of inner corners, ``(cols - 1) * (rows - 1)``."""
        return (self.cols - 1) * (self.rows - 1)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the whole board including the margin, board frame, metres."""
        s, m = self.square, self.margin
        return (-s - m, -s - m, (self.cols - 1) * s + m, (self.rows - 1) * s + m)

    def object_points(self) -> np.ndarray:
        """((cols-1)*(rows-1), 3) float64 inner corners, board frame, metres; row ``k`` is corner id ``k``."""
        i, j = np.divmod(np.arange(self.n_corners), self.cols - 1)
        return np.column_stack([j * self.square, i * self.square, np.zeros(self.n_corners)])

    def square_is_dark(self, r: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Whether square (row r, column c) is dark: ``(r + c)`` even. Square (r, c) spans
        x in ``[(c - 1) * square, c * square]``, y in ``[(r - 1) * square, r * square]``."""
        return (np.asarray(r) + np.asarray(c)) % 2 == 0

    def opencv_board(self) -> "cv2.aruco.CharucoBoard":
        """OpenCV's ``CharucoBoard`` for this board (its frame is ours shifted by +square in x and y)."""
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker, d)

    # ---------------------------------------------------------------- texture
    def texture(self, texel: float = 1e-4) -> tuple[np.ndarray, tuple[float, float, float, float]]:
        """The printed board as an albedo image.

        Parameters
        ----------
        texel : float
            Texel side in metres; ``square`` must be a whole number of texels (within 1e-6 of one), so
            every square edge falls exactly on a texel boundary. The margin is rounded up to whole texels.

        Returns
        -------
        image : (h, w) float32, read-only
            Albedo: ``dark`` or ``light`` (ChArUco markers are dark on the light squares).
        extent : (x0, y0, x1, y1)
            Board-frame rectangle the image covers, metres: row r, column c covers
            x in ``[x0 + c * texel, x0 + (c + 1) * texel]``, y in ``[y0 + r * texel, y0 + (r + 1) * texel]``.

        Raises
        ------
        InputError
            If ``texel`` is not positive or does not divide ``square``.
        """
        if not (isinstance(texel, (int, float, np.floating)) and np.isfinite(texel) and texel > 0):
            raise InputError(f"Board.texture: texel must be a finite number > 0 metres, found {texel!r}")
        n = self.square / texel
        if abs(n - round(n)) > 1e-6 * max(n, 1.0) or round(n) < 1:
            raise InputError(f"Board.texture: square ({self.square} m) must be a whole number of texels so square "
                             f"edges fall on texel boundaries; texel={texel} gives {n:.6g}; use e.g. "
                             f"texel={self.square / max(round(n), 1):.6g}")
        return _texture(self, float(texel))


@lru_cache(maxsize=8)
def _texture(board: Board, texel: float) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    n = int(round(board.square / texel))
    m = int(np.ceil(board.margin / texel - 1e-6))
    h, w = board.rows * n + 2 * m, board.cols * n + 2 * m
    check_budget(h * w * 12, f"the texture of a {board.cols}x{board.rows} board ({w}x{h} texels of {texel} m)")
    x0 = y0 = -board.square - m * texel
    extent = (x0, y0, x0 + w * texel, y0 + h * texel)
    img = np.full((h, w), board.light, np.float32)
    if board.kind == "checkerboard":
        r = np.arange(board.rows * n) // n
        c = np.arange(board.cols * n) // n
        inner = np.where(board.square_is_dark(r[:, None], c[None, :]), board.dark, board.light)
    else:
        # OpenCV draws markers inside the light squares; its first square is black (OpenCV >= 4.6).
        cv_img = board.opencv_board().generateImage((board.cols * n, board.rows * n), marginSize=0, borderBits=1)
        inner = np.where(cv_img < 128, board.dark, board.light)
    img[m: m + board.rows * n, m: m + board.cols * n] = inner
    img.flags.writeable = False
    return img, extent


forgettable_cache(_texture.cache_clear)


@dataclass(frozen=True)
class BoardDetection:
    """Board corners found in one image.

    ``ids``: (n,) int64 corner ids (rows of :meth:`Board.object_points`), increasing. ``uv``: (n, 2) float64
    pixel positions (u = column, v = row, pixel centres at integers). ``image_size``: (width, height).
    ``reason``: "" when found, else why not ("board not found", "only 5 of 54 corners (min_corners=6)").
    """

    ids: np.ndarray
    uv: np.ndarray
    image_size: tuple[int, int]
    reason: str = ""

    found = property(lambda self: self.reason == "")

    def __repr__(self) -> str:
        return (f"BoardDetection(found={self.found}, n={len(self.ids)}, image_size={self.image_size}, "
                f"reason={self.reason!r})")


def _failed(size: tuple[int, int], reason: str) -> BoardDetection:
    return BoardDetection(np.zeros(0, np.int64), np.zeros((0, 2)), size, reason)


def _as_gray(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """uint8/uint16 gray or RGB -> (float32 gray (:func:`rangekit.image.to_grey`), uint8 gray stretched to
    the image's maximum; uint8 input is not stretched)."""
    img = np.asarray(image)
    if img.dtype not in (np.uint8, np.uint16):
        raise InputError(f"detect_board: image dtype must be uint8 or uint16, found {img.dtype}")
    if img.ndim != 2 and not (img.ndim == 3 and img.shape[2] == 3):
        raise InputError(f"detect_board: image must be (H, W) gray or (H, W, 3) RGB, found shape {img.shape}")
    gray = to_grey(img) if img.ndim == 3 else img.astype(np.float32)
    if img.dtype == np.uint8 and img.ndim == 2:
        return gray, np.ascontiguousarray(img)
    top = 255.0 if img.dtype == np.uint8 else max(float(gray.max()), 1.0)
    return gray, np.rint(gray * (255.0 / top)).astype(np.uint8)


def detect_board(image: np.ndarray, board: Board, *, min_corners: int = 6,
                 symmetric_ok: bool = False) -> BoardDetection:
    """Find a board's inner corners in an image, with ids matching :meth:`Board.object_points`.

    Checkerboards: ``cv2.findChessboardCorners`` (adaptive threshold, normalised image; falling back to
    ``cv2.findChessboardCornersSB`` if it fails) finds the grid, then ``cv2.cornerSubPix`` refines every
    corner on the image smoothed by a Gaussian of ``SUBPIX_SIGMA`` = 1 px, with a window half-size of
    0.22 x the smallest corner spacing (3..15 px). Measured on simulator renders of the default rig
    (8 bits, ~1 % noise, 0.5 px lens blur, area-sampled texture) at the 15 ``board_poses(seed=0)``,
    810 corners, against the true projections (RMS / max):

    ==========================================================  =========  =========
    findChessboardCorners + smoothed cornerSubPix (this)        0.026 px   0.066 px
    findChessboardCorners + cornerSubPix on the raw image       0.040 px   0.082 px
    findChessboardCornersSB (CALIB_CB_ACCURACY)                 0.118 px   0.83 px
    findChessboardCorners alone                                 0.24 px    2.2 px
    ==========================================================  =========  =========

    so the SB detector is only the fallback finder (it is also ~50x slower: 0.75 s against 0.015 s).
    OpenCV may number the grid from either end, so the ids are resolved from the image: of the candidate
    orderings (both ends, mirrored, and read transposed) the one is kept that forms a grid, is seen from
    the printed side (board x then y turn clockwise in the image, v pointing down) and whose square
    centres, sampled through the corner homography, are dark where the board is dark (the (-x, -y)
    square included).

    ChArUco: ``cv2.aruco.CharucoDetector`` (markers refined with ``CORNER_REFINE_SUBPIX``), then the same
    smoothed ``cornerSubPix`` with the window kept inside the light gap between a corner and the markers
    (0.85 x the gap, about 0.1 x the corner spacing for markers of 0.75 square). ids are OpenCV's ChArUco
    ids, which equal ours. On the same 15 poses: RMS 0.033 px, max 0.089 px (the detector's own corners:
    RMS 0.044 px, max 0.13 px).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 or uint16 ndarray
        Gray or RGB capture (uint16 may hold any bit depth; it is stretched to 8 bits for the search and
        refined on the original values).
    board : Board
    min_corners : int
        Fewest corners to report the board found (ChArUco boards may be partly visible; a checkerboard
        is found whole or not at all).
    symmetric_ok : bool
        Accept a checkerboard with ``rows + cols`` even: ids known up to a half turn (corner 0 the one nearer
        the image's top-left), which poses each solved alone do not mind (a turntable's axis would).

    Returns
    -------
    BoardDetection
        ``found`` False with a ``reason`` when the board is not found, its orientation cannot be resolved
        or fewer than ``min_corners`` corners are seen.

    Raises
    ------
    InputError
        On a bad image, or a checkerboard with ``rows + cols`` even (symmetric: ids would be ambiguous).
    """
    if not isinstance(board, Board):
        raise InputError(f"detect_board: board must be a rangekit.boards.Board, found {type(board).__name__}")
    if not _is_int(min_corners) or min_corners < 1:
        raise InputError(f"detect_board: min_corners must be an integer >= 1, found {min_corners!r}")
    gray, gray8 = _as_gray(image)
    size = (gray.shape[1], gray.shape[0])
    if board.kind == "checkerboard":
        if (board.rows + board.cols) % 2 == 0 and not symmetric_ok:
            raise InputError(f"detect_board: a {board.cols}x{board.rows} checkerboard looks the same after a "
                             "180 degree turn, so its corner ids are ambiguous; use rows + cols odd (e.g. 10x7) "
                             "or a ChArUco board")
        if board.n_corners < min_corners:
            return _failed(size, f"the board has only {board.n_corners} corners (min_corners={min_corners})")
        return _detect_checkerboard(gray, gray8, board, size)
    return _detect_charuco(gray, gray8, board, size, min_corners)


#: Gaussian sigma (pixels) of the smoothing before cornerSubPix: it removes the pixel-phase bias of
#: cornerSubPix on sharp, area-sampled corners (see :func:`detect_board` for the figures).
SUBPIX_SIGMA = 1.0


def _refine(gray: np.ndarray, uv: np.ndarray, half: int) -> np.ndarray:
    smooth = cv2.GaussianBlur(gray, (0, 0), SUBPIX_SIGMA)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    out = cv2.cornerSubPix(smooth, uv.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), crit)
    return out.reshape(-1, 2).astype(np.float64)


def _min_spacing(uv: np.ndarray, ids: np.ndarray, board: Board) -> float:
    """Smallest image distance (pixels) between neighbouring detected corners."""
    grid = np.full((board.rows - 1, board.cols - 1, 2), np.nan)
    i, j = np.divmod(ids, board.cols - 1)
    grid[i, j] = uv
    d = np.concatenate([np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel(),
                        np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel()])
    return float(np.nanmin(d)) if np.any(np.isfinite(d)) else 20.0


def _detect_checkerboard(gray: np.ndarray, gray8: np.ndarray, board: Board, size) -> BoardDetection:
    w, h = board.cols - 1, board.rows - 1
    ok, corners = cv2.findChessboardCorners(gray8, (w, h),
                                            flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok or corners is None or len(corners) != w * h:
        ok, corners = cv2.findChessboardCornersSB(gray8, (w, h), flags=cv2.CALIB_CB_NORMALIZE_IMAGE
                                                  | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not ok or corners is None or len(corners) != w * h:
        return _failed(size, "board not found")
    uv = _orient_grid(corners.reshape(-1, 2).astype(np.float64), gray, board)
    if uv is None:
        return _failed(size, "board found but its orientation could not be resolved (seen from behind, or "
                             "too little contrast between dark and light squares)")
    if (board.rows + board.cols) % 2 == 0 and uv[-1].sum() < uv[0].sum():   # a half turn: corner 0 top-left
        uv = uv[::-1].copy()
    ids = np.arange(board.n_corners, dtype=np.int64)
    half = int(np.clip(round(0.22 * _min_spacing(uv, ids, board)), 3, 15))
    return BoardDetection(ids, _refine(gray, uv, half), size)


def _orient_grid(corners: np.ndarray, gray: np.ndarray, board: Board) -> np.ndarray | None:
    """(h*w, 2) corners in OpenCV's order -> (h*w, 2) uv in id order, or None if no ordering fits.

    Candidates: the corners read as h rows of w or, transposed, as w rows of h (read column by column),
    each from either end and mirrored. Kept: those that form a grid (a homography fits them to within a
    quarter of the corner spacing, which a wrong reading misses by about a spacing), seen from the
    printed side (x then y turn clockwise on screen, v down), and the one of those whose square centres
    are darkest where the board is dark.
    """
    h, w = board.rows - 1, board.cols - 1
    rowwise = corners.reshape(h, w, 2)
    colwise = corners.reshape(w, h, 2).swapaxes(0, 1)
    cands = [c for g in (rowwise, colwise) for c in (g, g[::-1, ::-1], g[::-1, :], g[:, ::-1])]
    obj = board.object_points()[:, :2]
    r, c = np.divmod(np.arange(board.rows * board.cols), board.cols)
    centres = np.column_stack([(c - 0.5) * board.square, (r - 0.5) * board.square])
    dark = board.square_is_dark(r, c)
    best, best_score = None, 0.5  # a right ordering scores about +1, one turned by 180 degrees about -1
    for g in cands:
        a, b = g[:-1, 1:] - g[:-1, :-1], g[1:, :-1] - g[:-1, :-1]
        if np.mean(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]) <= 0:
            continue
        uv = g.reshape(-1, 2)
        H, _ = cv2.findHomography(obj, uv, 0)
        if H is None:
            continue
        spacing = np.median(np.linalg.norm(a, axis=2))
        fit = cv2.perspectiveTransform(obj[None], H)[0]
        if np.sqrt(np.mean(np.sum((fit - uv) ** 2, axis=1))) > 0.25 * spacing:
            continue
        pts = cv2.perspectiveTransform(centres[None], H)[0].astype(np.float32)
        vals = cv2.remap(gray, pts[:, :1], pts[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=np.nan).ravel()
        ok = np.isfinite(vals)
        if ok[dark].sum() == 0 or ok[~dark].sum() == 0:
            continue
        # Separation of dark and light squares in units of the sampled values' spread.
        score = (np.mean(vals[ok & ~dark]) - np.mean(vals[ok & dark])) / (np.std(vals[ok]) + 1e-6)
        if score > best_score:
            best, best_score = uv, score
    return best


def _detect_charuco(gray: np.ndarray, gray8: np.ndarray, board: Board, size, min_corners: int) -> BoardDetection:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.CharucoDetector(board.opencv_board(), cv2.aruco.CharucoParameters(), params)
    corners, ids, _, marker_ids = detector.detectBoard(gray8)
    n_all = board.n_corners
    if ids is None or len(ids) == 0:
        what = "no ChArUco markers found" if marker_ids is None or len(marker_ids) == 0 else \
            f"{len(marker_ids)} markers but no corners"
        return _failed(size, f"board not found ({what})")
    ids = ids.ravel().astype(np.int64)
    if len(ids) < min_corners:
        return _failed(size, f"only {len(ids)} of {n_all} corners (min_corners={min_corners})")
    order = np.argsort(ids)
    ids, uv = ids[order], corners.reshape(-1, 2)[order].astype(np.float64)
    # Keep the window inside the light gap between the corner and the markers of its two light squares.
    gap = (board.square - board.marker) / 2 / board.square * _min_spacing(uv, ids, board)
    half = int(np.clip(np.floor(0.85 * gap), 2, 11))
    return BoardDetection(ids, _refine(gray, uv, half), size)
