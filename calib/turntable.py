"""Turntable axis from a board (or any rigid pattern) seen at several turntable angles.

The board is fixed on the turntable and the table is turned to angles ``theta_k`` (what the firmware
reports). Its pose in the camera at each angle, ``T_cam_board_k``, then satisfies

    T_cam_board_k = Rot(a, s * theta_k, c) @ T_cam_board_0

where ``Rot(a, phi, c)`` turns by ``phi`` about the axis with unit direction ``a`` through the point ``c``
(camera frame, metres) and ``s`` is the firmware's angle scale (1 if its degrees are true degrees).

:func:`fit_turntable_axis` starts from the relative motions (each ``T_k @ inv(T_0)`` is a rotation about
the axis: its rotation vector gives ``a`` and the angle, its fixed points give ``c``), then refines
``a``, ``c``, ``s`` and the board pose at angle 0 by minimising the corners' reprojection error in the
camera (Levenberg-Marquardt). The axis direction is oriented so that a positive firmware angle turns
counter-clockwise seen from ``+a`` (the rig file's convention for ``T_world_table``'s z axis).

:func:`turntable_frame` builds ``T_cam_table``: z along the axis, origin on the axis at the height of the
table top (from points on the top, e.g. triangulated from coded light), y horizontal from the camera
towards the axis, x = y x z. This is the simulator's world frame, so a calibrated rig file and the
simulator's true rig compare field by field.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares

from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError
from rangekit.geometry import R_to_rotvec, apply_T, invert_T, make_T, rotvec_to_R

__all__ = ["AxisFit", "fit_turntable_axis", "turntable_frame", "rotation_about_axis"]


def rotation_about_axis(axis: np.ndarray, angle: float, point: np.ndarray) -> np.ndarray:
    """(4, 4) rigid motion turning by ``angle`` radians about the line through ``point`` along unit ``axis``."""
    R = rotvec_to_R(np.asarray(axis, dtype=np.float64) * float(angle))
    p = np.asarray(point, dtype=np.float64)
    return make_T(R, p - R @ p)


@dataclass(frozen=True)
class AxisFit:
    """Turntable axis in the camera frame.

    ``direction`` (3,) unit; ``point`` (3,) metres, the point of the axis closest to the camera centre;
    ``angle_scale``: true angle / firmware angle; ``rms``: reprojection RMS of the board corners (px) at
    the fit; ``view_rms``: per angle (px); ``angles``: the firmware angles used (radians).
    """

    direction: np.ndarray
    point: np.ndarray
    angle_scale: float
    rms: float
    view_rms: tuple[float, ...]
    angles: tuple[float, ...]

    def summary_lines(self) -> list[str]:
        return [f"turntable axis (camera frame): direction {np.array2string(self.direction, precision=6)}, "
                f"point {np.array2string(self.point * 1e3, precision=3)} mm; reprojection RMS {self.rms:.4f} px "
                f"over {len(self.angles)} angles",
                f"angle scale: 1 firmware degree = {self.angle_scale:.5f} degrees"
                + ("" if abs(self.angle_scale - 1) < 0.002 else
                   " (check the firmware's steps per revolution or microstepping setting)")]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _perp_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e1 = _unit(np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0]))
    return e1, np.cross(a, e1)


def fit_turntable_axis(camera: PinholeCamera, object_points: np.ndarray, angles: Sequence[float],
                       observations: Sequence[tuple[np.ndarray, np.ndarray]],
                       T_cam_board: Sequence[np.ndarray]) -> AxisFit:
    """Fit the turntable axis from board corners seen at several firmware angles (module doc).

    Parameters
    ----------
    camera : calibrated camera (its pose is ignored; the fit is in its frame).
    object_points : (N, 3) board corners in the board frame, metres.
    angles : (K,) firmware turntable angles in radians, K >= 3 and spanning at least 20 degrees.
    observations : per angle, (ids (n,), uv (n, 2)) corners found in the camera image.
    T_cam_board : per angle, the board pose in the camera (e.g. ``cv2.solvePnP``), the starting point.
    """
    angles = np.asarray(angles, dtype=np.float64)
    K = len(angles)
    if K < 3 or len(observations) != K or len(T_cam_board) != K:
        raise CalibrationError(f"turntable: need the board at >= 3 angles with one observation and pose each, "
                               f"found {K} angles, {len(observations)} observations, {len(T_cam_board)} poses")
    if np.ptp(angles) < np.radians(20):
        raise CalibrationError(f"turntable: the angles span only {np.degrees(np.ptp(angles)):.1f} deg; turn the "
                               "table over at least 20 deg (60-80 deg is better) so the axis is well defined")
    order = np.argsort(np.abs(angles - angles.mean()))
    ref = int(order[0])                        # the middle angle is the reference pose
    T0 = T_cam_board[ref]
    rv, th, A, b = [], [], [], []
    for k in range(K):
        if k == ref:
            continue
        M = T_cam_board[k] @ invert_T(T0)
        rv.append(R_to_rotvec(M[:3, :3]))
        th.append(angles[k] - angles[ref])
        A.append(np.eye(3) - M[:3, :3])
        b.append(M[:3, 3])
    rv, th = np.array(rv), np.array(th)
    # rotvec = a * s * dtheta: the axis from a least-squares fit of rotvec against dtheta.
    a = _unit((rv * th[:, None]).sum(axis=0))
    s = float(np.sum((rv @ a) * th) / np.sum(th * th))
    c, *_ = np.linalg.lstsq(np.vstack(A), np.concatenate(b), rcond=None)
    c = c - (c @ a) * a                        # the axis point closest to the camera centre
    e1, e2 = _perp_basis(a)
    obj = np.asarray(object_points, dtype=np.float64)
    ids = [np.asarray(o[0]) for o in observations]
    uvs = [np.asarray(o[1], dtype=np.float64) for o in observations]
    x0 = np.concatenate([[0.0, 0.0, 0.0, 0.0, s], R_to_rotvec(T0[:3, :3]), T0[:3, 3]])

    def unpack(x):
        ax = _unit(a + x[0] * e1 + x[1] * e2)
        pt = c + x[2] * e1 + x[3] * e2
        return ax, pt, x[4], make_T(rotvec_to_R(x[5:8]), x[8:11])

    def residuals(x):
        ax, pt, scale, Tref = unpack(x)
        out = []
        for k in range(K):
            T = rotation_about_axis(ax, scale * (angles[k] - angles[ref]), pt) @ Tref
            out.append((camera.project_cam(apply_T(T, obj[ids[k]])) - uvs[k]).ravel())
        return np.concatenate(out)

    sol = least_squares(residuals, x0, method="lm", x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    ax, pt, scale, _ = unpack(sol.x)
    pt = pt - (pt @ ax) * ax
    if scale < 0:
        ax, scale = -ax, -scale
    r = residuals(sol.x).reshape(-1, 2)
    sizes = np.cumsum([0] + [len(i) for i in ids])
    view_rms = tuple(float(np.sqrt(np.mean(np.sum(r[sizes[k]:sizes[k + 1]] ** 2, axis=1)))) for k in range(K))
    return AxisFit(direction=ax, point=pt, angle_scale=float(scale),
                   rms=float(np.sqrt(np.mean(np.sum(r ** 2, axis=1)))), view_rms=view_rms,
                   angles=tuple(float(t) for t in angles))


def turntable_frame(axis: AxisFit, table_points: np.ndarray | None = None, *,
                    bin_size: float = 5e-4) -> tuple[np.ndarray, float | None]:
    """``T_cam_table`` (4, 4) from a fitted axis, and the table-top height used (metres along the axis from
    ``axis.point``, None without table points).

    ``table_points`` (N, 3), camera frame: points of the scene at one angle (e.g. triangulated from coded
    light) that include the table top. The table top is the densest height along the axis (a histogram
    of ``bin_size`` metres, refined by the median within 1 mm): a plane perpendicular to the axis piles
    up in one bin while the board and the object spread over many. Without them the origin is
    ``axis.point`` (the axis point closest to the camera).
    """
    a = axis.direction
    height = None
    origin = axis.point.copy()
    if table_points is not None:
        P = np.asarray(table_points, dtype=np.float64).reshape(-1, 3)
        P = P[np.all(np.isfinite(P), axis=1)]
        if len(P) < 100:
            raise CalibrationError(f"turntable: only {len(P)} table points to find the table top (100 needed)")
        h = (P - axis.point) @ a
        lo, hi = np.percentile(h, [0.5, 99.5])
        bins = max(int(np.ceil((hi - lo) / bin_size)), 1)
        counts, edges = np.histogram(h, bins=bins, range=(lo, hi))
        peak = 0.5 * (edges[np.argmax(counts)] + edges[np.argmax(counts) + 1])
        near = np.abs(h - peak) < 1e-3
        height = float(np.median(h[near]))
        origin = axis.point + height * a
    y = origin - (origin @ a) * a              # horizontal (perpendicular to the axis) from the camera to the axis
    if np.linalg.norm(y) < 1e-9:
        raise CalibrationError("turntable: the camera centre lies on the turntable axis; cannot orient the table frame")
    y = _unit(y)
    x = np.cross(y, a)
    return make_T(np.column_stack([x, y, a]), origin), height
