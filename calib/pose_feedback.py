"""Feedback on each calibration board pose as it is captured: keep it, or say why not so it can be retaken.

:func:`check_pose` judges one detection (camera pixels) against :class:`FeedbackLimits`, in this order:
board not found; too few corners; too small in the image (the corners' convex hull, as a fraction of the
image); too oblique (angle between the board's normal and the camera ray to its centre); reprojection
error above the limit. The reprojection error is that of a quick single-pose fit (focal length, k1 and the
pose; principal point at the image centre) until 3 poses are kept, then of the pose fitted by PnP against
the camera calibrated from the kept poses so far.

:func:`coverage_image` draws which parts of the camera image the kept poses' corners have covered
(``coverage.png``): a grid of :data:`COVERAGE_GRID` cells shaded by how many poses put a corner in them,
every kept corner as a dot, the last pose's corners in yellow (kept) or red (rejected).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from rangekit.boards import Board, BoardDetection
from rangekit.calib.camera import DEFAULT_FLAGS

__all__ = ["FeedbackLimits", "PoseCheck", "check_pose", "coverage_grid", "coverage_image", "COVERAGE_GRID"]

COVERAGE_GRID = (16, 12)          # (columns, rows) of cells the coverage fraction counts
_MAX_PNG_SIDE = 640               # the coverage PNG is scaled down to this width


@dataclass(frozen=True)
class FeedbackLimits:
    """When a board pose is rejected. ``min_area_fraction``: the corners' convex hull over the image area;
    ``max_tilt_deg``: degrees between the board normal and the camera ray to the board centre;
    ``max_reprojection_px``: RMS of the pose's corners, camera pixels."""

    min_corners: int = 12
    min_area_fraction: float = 0.02
    max_tilt_deg: float = 65.0
    max_reprojection_px: float = 1.0


@dataclass(frozen=True)
class PoseCheck:
    """The verdict on one captured board pose (``index`` from 0). ``reprojection_px``, ``tilt_deg`` and
    ``area_fraction`` are nan when they could not be measured; ``fit`` names the reprojection's model;
    ``coverage`` is the fraction of :data:`COVERAGE_GRID` cells holding a kept corner, this pose included
    when kept; ``reason`` is "" for a kept pose."""

    index: int
    n_corners: int
    reprojection_px: float
    tilt_deg: float
    area_fraction: float
    fit: str
    coverage: float
    reason: str = ""
    normal: tuple[float, float, float] = (float("nan"),) * 3   # board z axis, camera frame (facing it: (0, 0, 1))
    corners: np.ndarray | None = field(default=None, compare=False, repr=False)   # (n, 2) camera px, as detected

    @property
    def accepted(self) -> bool:
        return self.reason == ""

    def line(self) -> str:
        head = f"pose {self.index + 1}: "
        if self.n_corners == 0:
            return head + f"rejected: {self.reason}"
        facts = (f"{self.n_corners} corners, reprojection {self.reprojection_px:.3f} px ({self.fit}), tilt "
                 f"{self.tilt_deg:.0f} deg, {self.area_fraction * 100:.0f}% of the image; coverage "
                 f"{self.coverage * 100:.0f}%")
        return head + ("kept: " + facts if self.accepted else f"rejected: {self.reason} ({facts})")


def _rms(obj: np.ndarray, uv: np.ndarray, K: np.ndarray, dist: np.ndarray, rvec, tvec) -> float:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - uv) ** 2, axis=1))))


def _single_pose_fit(obj: np.ndarray, uv: np.ndarray, size: tuple[int, int]):
    """(K, dist, rvec, tvec) from one view: focal length (square pixels), k1 and the pose; the principal
    point at the image centre (a shift of it is mostly absorbed by the pose)."""
    w, h = size
    K0 = np.array([[float(w), 0.0, (w - 1) / 2], [0.0, float(w), (h - 1) / 2], [0.0, 0.0, 1.0]])
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3)
    _, K, dist, rvecs, tvecs = cv2.calibrateCamera([obj.astype(np.float32)], [uv.astype(np.float32)], (w, h),
                                                   K0, np.zeros(5), flags=flags)
    return K, dist.ravel(), rvecs[0], tvecs[0]


def _calibrated_fit(obj_all: np.ndarray, kept: Sequence[tuple[np.ndarray, np.ndarray]], obj: np.ndarray,
                    uv: np.ndarray, size: tuple[int, int]):
    """(K, dist, rvec, tvec): the camera calibrated from the kept poses, this pose by PnP against it."""
    _, K, dist, _, _ = cv2.calibrateCamera([obj_all[ids].astype(np.float32) for ids, _ in kept],
                                           [u.astype(np.float32) for _, u in kept], tuple(size), None, None,
                                           flags=DEFAULT_FLAGS)
    _, rvec, tvec = cv2.solvePnP(obj, uv, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
    return K, dist.ravel(), rvec, tvec


def coverage_grid(kept: Sequence[tuple[np.ndarray, np.ndarray]], size: tuple[int, int]) -> np.ndarray:
    """(rows, cols) int: per :data:`COVERAGE_GRID` cell, how many kept poses put a corner in it.
    ``kept``: per pose (ids (n,), uv (n, 2) camera pixels); ``size``: (width, height)."""
    gc, gr = COVERAGE_GRID
    counts = np.zeros((gr, gc), np.int64)
    w, h = size
    for _, uv in kept:
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        c = np.clip(((uv[:, 0] + 0.5) / w * gc).astype(int), 0, gc - 1)
        r = np.clip(((uv[:, 1] + 0.5) / h * gr).astype(int), 0, gr - 1)
        hit = np.zeros((gr, gc), bool)
        hit[r, c] = True
        counts += hit
    return counts


def check_pose(index: int, det: BoardDetection, board: Board, size: tuple[int, int], *,
               kept: Sequence[tuple[np.ndarray, np.ndarray]] = (),
               limits: FeedbackLimits = FeedbackLimits()) -> PoseCheck:
    """Judge the board pose ``index`` (module doc) from its detection ``det`` in a camera image of ``size``
    (width, height) pixels; ``kept`` holds the (ids, uv) of the poses kept before it."""
    w, h = size
    nan = float("nan")

    def cover(extra=()) -> float:
        return float(np.mean(coverage_grid(list(kept) + list(extra), size) > 0))

    if not det.found:
        return PoseCheck(index, 0, nan, nan, nan, "", cover(), det.reason or "board not found")
    ids, uv = np.asarray(det.ids), np.asarray(det.uv, np.float64).reshape(-1, 2)
    n = len(ids)
    if n < limits.min_corners:
        return PoseCheck(index, n, nan, nan, nan, "", cover(),
                         f"too few corners: {n}, at least {limits.min_corners} needed", corners=uv)
    obj = board.object_points()[ids]
    area = float(cv2.contourArea(cv2.convexHull(uv.astype(np.float32)))) / (w * h)
    if len(kept) >= 3:
        fit = f"against the calibration of {len(kept)} kept poses"
        K, dist, rvec, tvec = _calibrated_fit(board.object_points(), kept, obj, uv, size)
    else:
        fit = "single-pose fit"
        K, dist, rvec, tvec = _single_pose_fit(obj, uv, size)
    rms = _rms(obj, uv, K, dist, rvec, tvec)
    R, _ = cv2.Rodrigues(rvec)
    centre = R @ obj.mean(axis=0) + np.ravel(tvec)
    tilt = float(np.degrees(np.arccos(min(1.0, abs(R[:, 2] @ centre) / np.linalg.norm(centre)))))
    reason = ""
    if area < limits.min_area_fraction:
        reason = (f"too small in the image: the board covers {area * 100:.1f}% of it, at least "
                  f"{limits.min_area_fraction * 100:g}% needed; bring it closer")
    elif tilt > limits.max_tilt_deg:
        reason = f"too oblique: tilted {tilt:.0f} deg from the camera ray, at most {limits.max_tilt_deg:g} deg"
    elif not rms <= limits.max_reprojection_px:
        reason = (f"reprojection error {rms:.3f} px above {limits.max_reprojection_px:g} px (motion blur, a bent "
                  "board or a misdetection)")
    return PoseCheck(index, n, rms, tilt, area, fit, cover([] if reason else [(ids, uv)]), reason,
                     tuple(float(x) for x in R[:, 2]), uv)


def coverage_image(kept: Sequence[tuple[np.ndarray, np.ndarray]], size: tuple[int, int],
                   last: np.ndarray | None = None, last_kept: bool = True) -> np.ndarray:
    """(H', W', 3) uint8 RGB picture of the coverage (module doc), the camera image scaled to at most
    :data:`_MAX_PNG_SIDE` pixels wide. ``last``: (n, 2) camera pixels of the latest pose's corners."""
    w, h = size
    s = min(1.0, _MAX_PNG_SIDE / w)
    W, H = max(1, int(round(w * s))), max(1, int(round(h * s)))
    counts = coverage_grid(kept, size).astype(np.float64)
    shade = np.clip(counts / 3.0, 0.0, 1.0)                      # three poses per cell: full green
    cells = cv2.resize(shade.astype(np.float32), (W, H), interpolation=cv2.INTER_NEAREST)
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = 30
    img[..., 1] = (30 + 150 * cells).astype(np.uint8)
    img[..., 2] = 30
    gc, gr = COVERAGE_GRID
    img[(np.arange(H) * gr // H) != ((np.arange(H) + 1) * gr // H), :] = 70      # grid lines
    img[:, (np.arange(W) * gc // W) != ((np.arange(W) + 1) * gc // W)] = 70
    pts = [np.asarray(uv, np.float64).reshape(-1, 2) for _, uv in kept]

    def dots(uv: np.ndarray, colour, r: int) -> None:
        p = np.clip(np.round((uv + 0.5) * s - 0.5).astype(int), 0, [W - 1, H - 1])
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                img[np.clip(p[:, 1] + dy, 0, H - 1), np.clip(p[:, 0] + dx, 0, W - 1)] = colour

    if pts:
        dots(np.concatenate(pts), (220, 220, 220), 0)
    if last is not None and len(last):
        dots(np.asarray(last, np.float64).reshape(-1, 2), (255, 220, 0) if last_kept else (255, 40, 40), 1)
    return img
