"""Camera calibration from board detections (Zhang's method via OpenCV), with per-view errors, automatic
rejection of bad views (each with its reason) and a check for degenerate (nearly parallel) board poses.

The same function calibrates a projector as an inverse camera: give it the projector coordinates of the
board corners (:mod:`rangekit.calib.projector`) and the projector's resolution.

Frames: the board frame is :meth:`rangekit.boards.Board.object_points`'s (metres); ``T_cam_board`` maps
board coordinates into the calibrated device's frame (OpenCV: x right, y down, z forward).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError
from rangekit.geometry import make_T, rotvec_to_R

__all__ = ["ViewReport", "DeviceCalibration", "Correspondences", "calibrate_device", "board_normal_spread",
           "DEFAULT_FLAGS", "CalibrationWarning", "LensModel", "LENS_MODELS", "CORNER_FITS"]

#: Five coefficients (k1, k2, p1, p2, k3) with k3 fixed at 0: a board seldom covers the corners of the image
#: well enough to separate k3 from k1, k2 (it then absorbs noise and extrapolates badly).
DEFAULT_FLAGS = cv2.CALIB_FIX_K3


@dataclass(frozen=True)
class LensModel:
    """What a calibration fits of the camera and of the projector: OpenCV flags for :func:`calibrate_device`
    and the same as the intrinsics :func:`rangekit.calib.projector.bundle_adjust` holds (its ``fixed_*``)."""

    name: str
    description: str
    camera_flags: int
    projector_flags: int
    camera_fixed: tuple[str, ...] = ()
    projector_fixed: tuple[str, ...] = ()


#: How a board corner's projector coordinates are fitted from the decoded maps around it, the default first:
#: rangekit's robust local quadratic (:func:`rangekit.calib.projector.corner_projector_coords`) or Moreno and
#: Taubin's local homography (:func:`rangekit.calib.local_homography.local_homography_coords`). Here, beside the
#: lens models, so the command line lists both without loading the solvers.
CORNER_FITS = ("quadratic", "homography")

_RADIAL = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
_K1 = _RADIAL | cv2.CALIB_FIX_K2
_SQUARE = cv2.CALIB_FIX_ASPECT_RATIO

#: The lens models ``rangekit calibrate --lens`` offers, by name; "k1k2p" is rangekit's default. "slstudio"
#: is SLStudio's calibrator's (``CalibratorLocHom.cpp``): k1 alone and square pixels for both devices, the
#: camera's principal point held at the image centre.
LENS_MODELS = {
    "k1k2p": LensModel("k1k2p", "k1, k2, p1, p2 (k3 0)", DEFAULT_FLAGS, DEFAULT_FLAGS),
    "k1k2": LensModel("k1k2", "k1, k2 (no tangential terms)", _RADIAL, _RADIAL, ("p1", "p2"), ("p1", "p2")),
    "k1": LensModel("k1", "k1 alone", _K1, _K1, ("k2", "p1", "p2"), ("k2", "p1", "p2")),
    "slstudio": LensModel("slstudio", "SLStudio's: k1 alone, square pixels, the camera's principal point at the "
                          "image centre", _K1 | _SQUARE | cv2.CALIB_FIX_PRINCIPAL_POINT, _K1 | _SQUARE,
                          ("k2", "p1", "p2", "aspect", "cx", "cy"), ("k2", "p1", "p2", "aspect")),
}


class CalibrationWarning(UserWarning):
    """A view was rejected or a result is poorly conditioned; the calibration still completed."""


@dataclass(frozen=True)
class Correspondences:
    """Board corners seen in one view by one device.

    ``ids`` (n,) int index :meth:`Board.object_points`; ``uv`` (n, 2) float64 pixels of the device
    (camera pixels, or projector pixels for a projector); ``reason`` is why the view has no usable corners
    ("" when it has).
    """

    ids: np.ndarray
    uv: np.ndarray
    reason: str = ""

    @property
    def n(self) -> int:
        return int(len(self.ids))


@dataclass(frozen=True)
class ViewReport:
    """What happened to one view: used or rejected, its reprojection RMS (px) and the reason."""

    index: int
    name: str
    used: bool
    n_corners: int
    rms: float = float("nan")    # px, this view's reprojection RMS at the final estimate (nan if unused)
    reason: str = ""             # why it was rejected ("" if used)

    def line(self) -> str:
        if self.used:
            return f"{self.name}: {self.n_corners} corners, RMS {self.rms:.3f} px"
        return f"{self.name}: rejected: {self.reason}"


@dataclass(frozen=True, eq=False)
class DeviceCalibration:
    """Result of :func:`calibrate_device`.

    ``device``: the calibrated model (``T_world_cam`` = identity: world = the device's own frame).
    ``rms``: reprojection RMS over every used corner, px. ``std``: one standard deviation of
    (fx, fy, cx, cy, k1, k2, p1, p2, k3) from OpenCV's covariance. ``T_dev_board``: per view index, the
    board pose in the device frame (only used views). ``views``: one report per input view.
    """

    device: PinholeCamera
    rms: float
    std: np.ndarray
    views: tuple[ViewReport, ...]
    T_dev_board: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    @property
    def used(self) -> list[int]:
        return [v.index for v in self.views if v.used]

    def summary_lines(self) -> list[str]:
        K = self.device.K
        d = self.device.dist
        lines = [f"{self.device.name}: {len(self.used)}/{len(self.views)} views, reprojection RMS {self.rms:.4f} px",
                 f"  fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} cx {K[0, 2]:.2f} cy {K[1, 2]:.2f} "
                 f"(+- {self.std[0]:.2f} {self.std[1]:.2f} {self.std[2]:.2f} {self.std[3]:.2f}); "
                 f"dist {' '.join(f'{x:.5f}' for x in d)}"]
        lines += ["  " + v.line() for v in self.views]
        lines += [f"  warning: {w}" for w in self.warnings]
        return lines


def board_normal_spread(T_dev_board: Sequence[np.ndarray]) -> float:
    """Largest angle (radians) between the board normals of any two poses ``T_dev_board`` (4, 4)."""
    n = np.array([T[:3, 2] for T in T_dev_board])
    if len(n) < 2:
        return 0.0
    c = np.clip(np.abs(n @ n.T), -1.0, 1.0)
    return float(np.arccos(c.min()))


def _guess_poses(obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int]) -> list[np.ndarray]:
    """Board poses from a rough pinhole guess (f = image width, centred, no distortion); for the
    degeneracy check before any calibration. Normals are good to a few degrees."""
    w, h = size
    K = np.array([[float(w), 0, (w - 1) / 2], [0, float(w), (h - 1) / 2], [0, 0, 1]])
    out = []
    for o, i in zip(obj, img):
        ok, rvec, tvec = cv2.solvePnP(o, i, K, None, flags=cv2.SOLVEPNP_IPPE)
        out.append(make_T(rotvec_to_R(rvec.ravel()), tvec.ravel()) if ok else np.eye(4))
    return out


def calibrate_device(views: Sequence[Correspondences | None], object_points: np.ndarray,
                     size: tuple[int, int], *, name: str = "camera", names: Sequence[str] | None = None,
                     flags: int = DEFAULT_FLAGS, min_corners: int = 6, min_views: int = 3,
                     outlier_factor: float = 4.0, outlier_floor_px: float = 0.3,
                     min_spread_deg: float = 8.0, max_rel_std: float = 0.02) -> DeviceCalibration:
    """Calibrate a camera (or a projector as an inverse camera) from board corners in several views.

    Parameters
    ----------
    views : per view, the corners seen (None or zero corners: the view is skipped with its ``reason``).
    object_points : (N, 3) board corners in the board frame, metres (``Board.object_points()``).
    size : (width, height) of the device in pixels.
    name : the device's name in the result and in messages.
    names : per view, a name for messages (default ``view_000``, ...).
    flags : OpenCV calibration flags (default: 5 coefficients with k3 fixed at 0).
    min_corners : views with fewer corners are rejected.
    min_views : fewer usable views than this raise :class:`CalibrationError`.
    outlier_factor, outlier_floor_px : after a first solve, a view whose RMS exceeds
        ``max(outlier_factor * median view RMS, outlier_floor_px)`` is rejected and the rest re-solved
        (a misdetected board, motion blur, a bent board).
    min_spread_deg : if the board normals of all usable views lie within this angle of each other the
        poses are degenerate for Zhang's method (focal length and distance trade off):
        :class:`CalibrationError` naming the views.
    max_rel_std : a focal length whose standard deviation exceeds this fraction of its value gives a
        :class:`CalibrationWarning` (poorly conditioned: add views with more tilt).

    Raises
    ------
    CalibrationError
        Fewer than ``min_views`` usable views, or degenerate poses. The message lists every view and why.
    """
    obj_all = np.asarray(object_points, dtype=np.float64)
    names = list(names) if names is not None else [f"view_{i:03d}" for i in range(len(views))]
    w, h = int(size[0]), int(size[1])
    reports: dict[int, ViewReport] = {}
    obj, img, idx = [], [], []
    for i, v in enumerate(views):
        if v is None or v.n == 0:
            reason = (v.reason if v is not None and v.reason else "board not found")
            reports[i] = ViewReport(i, names[i], False, 0, reason=reason)
        elif v.n < min_corners:
            reports[i] = ViewReport(i, names[i], False, v.n,
                                    reason=f"only {v.n} corners (at least {min_corners} needed)")
        else:
            obj.append(obj_all[np.asarray(v.ids)].astype(np.float32))
            img.append(np.asarray(v.uv, dtype=np.float32).reshape(-1, 1, 2))
            idx.append(i)

    def fail_if_too_few(extra: str = "") -> None:
        if len(idx) < min_views:
            detail = "; ".join(reports[i].line() for i in sorted(reports) if not reports[i].used)
            raise CalibrationError(
                f"{name}: only {len(idx)} usable view(s) of {len(views)}, at least {min_views} needed{extra}"
                + (f" ({detail})" if detail else "") + "; capture more views with the whole board visible")

    fail_if_too_few()
    spread = np.degrees(board_normal_spread(_guess_poses(obj, img, (w, h))))
    if spread < min_spread_deg:
        raise CalibrationError(
            f"{name}: the board poses of views {', '.join(names[i] for i in idx)} are nearly parallel (their "
            f"normals lie within {spread:.1f} deg of each other, at least {min_spread_deg:g} deg needed): "
            "focal length and distance cannot be separated; tilt the board by 20-40 deg in different "
            "directions between views")

    notes: list[str] = []
    while True:
        rms, K, dist, rvecs, tvecs, std_int, _, per_view = cv2.calibrateCameraExtended(
            obj, [i.astype(np.float32) for i in img], (w, h), None, None, flags=flags,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
        per_view = per_view.ravel()
        limit = max(outlier_factor * float(np.median(per_view)), outlier_floor_px)
        worst = int(np.argmax(per_view))
        if per_view[worst] <= limit or len(idx) <= min_views:
            break
        i = idx[worst]
        reports[i] = ViewReport(i, names[i], False, len(obj[worst]),
                                reason=f"reprojection RMS {per_view[worst]:.3f} px, above {limit:.3f} px "
                                       f"({outlier_factor:g} x the median view, or {outlier_floor_px:g} px)")
        notes.append(f"{names[i]} rejected: {reports[i].reason}")
        del obj[worst], img[worst], idx[worst]
        fail_if_too_few(" after rejecting outliers")

    std = std_int.ravel()[:9].copy()
    poses = {}
    for k, i in enumerate(idx):
        reports[i] = ViewReport(i, names[i], True, len(obj[k]), rms=float(per_view[k]))
        poses[i] = make_T(rotvec_to_R(rvecs[k].ravel()), tvecs[k].ravel())
    for fi, label in ((0, "fx"), (1, "fy")):
        if std[fi] > max_rel_std * K[fi, fi]:
            notes.append(f"{label} is poorly determined (+- {std[fi]:.1f} px of {K[fi, fi]:.1f}): add views "
                         "with more tilt")
    for note in notes:
        warnings.warn(f"{name}: {note}", CalibrationWarning, stacklevel=2)
    n_dist = 5
    device = PinholeCamera(K=K, width=w, height=h, dist=np.asarray(dist, dtype=np.float64).ravel()[:n_dist],
                           name=name)
    return DeviceCalibration(device=device, rms=float(rms), std=std,
                             views=tuple(reports[i] for i in range(len(views))), T_dev_board=poses,
                             warnings=tuple(notes))
