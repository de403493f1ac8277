"""The camera and the projector from board corners: each calibrated alone, then bundle-adjusted together.

The step every rig calibration shares (:func:`rangekit.calib.procedure.calibrate_rig` on devices,
:func:`rangekit.calib.recorded.calibrate_recorded` on recorded sequences): given, per board pose, the corners
the camera found and the projector coordinates of those corners (a :class:`~rangekit.calib.projector.CornerFit`
from the decoded coded light),

1. the camera alone (:func:`rangekit.calib.camera.calibrate_device`: Zhang's method, bad poses rejected with
   their reason);
2. the projector alone as an inverse camera, from the poses the camera kept;
3. the projector's pose from both devices' board poses (:func:`rangekit.calib.projector.initial_T_proj_cam`),
   then :func:`rangekit.calib.projector.bundle_adjust` of both devices' intrinsics, that pose and every board
   pose, each device's corners weighted by its own noise (its RMS alone over sqrt 2).

The :class:`~rangekit.calib.camera.LensModel` names what each device fits. Frames: world = the camera's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rangekit.calib.camera import LENS_MODELS, Correspondences, DeviceCalibration, LensModel, calibrate_device
from rangekit.calib.projector import BundleResult, CornerFit, bundle_adjust, initial_T_proj_cam

__all__ = ["PairCalibration", "calibrate_pair"]


@dataclass(frozen=True, eq=False)
class PairCalibration:
    """What :func:`calibrate_pair` found: each device alone, the bundle adjustment (its ``camera`` and
    ``projector`` are the result; world = the camera's frame) and the median standard error of the corners'
    projector coordinates (projector pixels)."""

    camera: DeviceCalibration
    projector: DeviceCalibration
    bundle: BundleResult
    corner_std_projector: float
    lens: LensModel


def _empty(reason: str) -> Correspondences:
    return Correspondences(np.zeros(0, np.int64), np.zeros((0, 2)), reason)


def calibrate_pair(cam_views: Sequence[Correspondences], proj_fits: Sequence[CornerFit | None],
                   object_points: np.ndarray, camera_size: tuple[int, int], projector_size: tuple[int, int], *,
                   names: Sequence[str], lens: LensModel = LENS_MODELS["k1k2p"]) -> PairCalibration:
    """Calibrate the camera and the projector from board corners (module doc).

    Parameters
    ----------
    cam_views : per board pose, the corners the camera found (no corners: the pose is skipped with its reason).
    proj_fits : per board pose, the projector coordinates of ``cam_views[i]``'s corners, row for row (NaN rows:
        not lit), or None where there are none.
    object_points : (N, 3) board corners, board frame, metres (``Board.object_points()``).
    camera_size, projector_size : (width, height) pixels.
    names : per pose, its name in messages ("pose 1", a folder's name).
    lens : what each device fits (:data:`rangekit.calib.camera.LENS_MODELS`).

    Raises
    ------
    CalibrationError
        Too few usable poses for either device, or degenerate (nearly parallel) poses, naming the poses.
    """
    obj = np.asarray(object_points, dtype=np.float64)
    cam_cal = calibrate_device(cam_views, obj, camera_size, name="camera", names=names, flags=lens.camera_flags)
    proj_views, stds = [], []
    for i, (view, fit) in enumerate(zip(cam_views, proj_fits)):
        if fit is None or i not in cam_cal.T_dev_board:
            proj_views.append(_empty(view.reason or "not used for the camera"))
            continue
        ok = fit.ok
        stds.append(fit.std[ok].ravel())
        proj_views.append(Correspondences(view.ids[ok], fit.proj_uv[ok],
                                          "" if ok.any() else "no corner lit by the projector"))
    proj_cal = calibrate_device(proj_views, obj, projector_size, name="projector", names=names,
                                flags=lens.projector_flags)
    T_proj_cam = initial_T_proj_cam(cam_cal.T_dev_board, proj_cal.T_dev_board)
    common = sorted(set(cam_cal.T_dev_board) & set(proj_cal.T_dev_board))
    corner_std = float(np.median(np.concatenate(stds))) if stds else float("nan")
    bundle = bundle_adjust(cam_cal.device, proj_cal.device, T_proj_cam,
                           {i: cam_cal.T_dev_board[i] for i in common}, obj,
                           {i: (cam_views[i].ids, cam_views[i].uv) for i in common},
                           {i: (proj_views[i].ids, proj_views[i].uv) for i in common},
                           sigma_camera=max(cam_cal.rms / np.sqrt(2), 1e-3),
                           sigma_projector=max(proj_cal.rms / np.sqrt(2), 1e-3),
                           fixed_camera=lens.camera_fixed, fixed_projector=lens.projector_fixed)
    return PairCalibration(cam_cal, proj_cal, bundle, corner_std, lens)
