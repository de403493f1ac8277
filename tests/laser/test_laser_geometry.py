"""Laser triangulation and laser-plane calibration against exact synthetic geometry.

The camera is the simulator's default (1800 px focal length, k1 = -0.08, k2 = 0.12), the laser plane a
Ciclop-like sheet through the turntable axis at 30 degrees to the camera; board poses are tilted up to
30 degrees about random axes near the axis. Line points on a board are projected with the camera's own
distortion (``PinholeCamera.project``), 0.3 mm apart, and optionally perturbed by 0.05 px.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rangekit.boards import Board
from rangekit.errors import CalibrationError, ConfigError
from rangekit.camera import PinholeCamera
from rangekit.geometry import apply_T, axis_angle_to_R, compose, invert_T, look_at, make_T
from rangekit.laser.plane_calib import (board_view, calibrate_laser_plane, calibrated_laser, plane_errors,
                                        plate_view, report_lines)
from rangekit.laser.plane_fit import fit_plane
from rangekit.laser.triangulate import to_turntable_frame, triangulate_peaks
from rangekit.rig.lasers import LineLaser, laser_plane
from rangekit.rig.rig_file import table_frame, table_motion
from rangekit.sim import default_rig

BOARD = Board()
RIG = default_rig()
CAM = RIG.camera
# Ciclop-like: the plane holds the table axis (z) and the direction 30 degrees off the camera's.
EMIT = np.array([math.sin(math.radians(30)), -math.cos(math.radians(30)), 0.0])
TRUE_PLANE = laser_plane(np.cross([0.0, 0.0, 1.0], EMIT), [0.0, 0.0, 0.0], towards=CAM.center)
LASER = LineLaser(plane=TRUE_PLANE, name="laser0", switch=1, channel="red")


def board_pose(rng, centre=(0.0, 0.0, 0.07), tilt_deg=30.0, shift=0.02) -> np.ndarray:
    """T_world_board: the board's middle near ``centre``, facing the camera, tilted at random."""
    c = np.asarray(centre) + rng.uniform(-shift, shift, 3)
    T = look_at(c, CAM.center)  # z towards the camera
    axis = rng.normal(size=3)
    R = axis_angle_to_R(axis / np.linalg.norm(axis), math.radians(rng.uniform(-tilt_deg, tilt_deg))) @ T[:3, :3]
    x0, y0, x1, y1 = BOARD.extent
    mid = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    return make_T(R, c - R @ mid)


def line_on_target(T_world_target, plane=TRUE_PLANE, extent=BOARD.extent, step=3e-4, clip=True) -> np.ndarray:
    """(M, 3) world points of the laser line on the target's z = 0 plane, inside ``extent`` when ``clip``."""
    R, t = T_world_target[:3, :3], T_world_target[:3, 3]
    a = R.T @ plane[:3]                      # plane in the target frame: a . x + b = 0
    b = plane[3] + plane[:3] @ t
    n2 = a[:2] / np.linalg.norm(a[:2])
    p0 = -b / np.linalg.norm(a[:2]) * n2
    s = np.arange(-0.4, 0.4, step)
    xy = p0 + s[:, None] * np.array([-n2[1], n2[0]])
    if clip:
        x0, y0, x1, y1 = extent
        xy = xy[(xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)]
    return apply_T(T_world_target, np.column_stack([xy, np.zeros(len(xy))]))


def image_points(X, noise=0.0, rng=None) -> tuple[np.ndarray, np.ndarray]:
    uv = CAM.project(X)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= CAM.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= CAM.height - 1)
    uv, X = uv[inside], X[inside]
    if noise:
        uv = uv + rng.normal(scale=noise, size=uv.shape)
    return uv, X


def views(n, noise, seed=1):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        T = board_pose(rng)
        uv, _ = image_points(line_on_target(T), noise, rng)
        out.append(board_view(BOARD, uv, T, name=f"board pose {i + 1}"))
    return out


# ------------------------------------------------------------------------------------------ triangulation
def test_triangulate_peaks_exact_with_distortion():
    rng = np.random.default_rng(0)
    X = np.concatenate([line_on_target(board_pose(rng)) for _ in range(3)])
    uv, X = image_points(X)
    assert len(uv) > 300
    res = triangulate_peaks(uv, CAM, LASER)
    assert res.valid.all() and res.n_grazing == res.n_behind == res.n_invalid == 0
    assert np.max(np.linalg.norm(res.xyz - X, axis=1)) < 1e-9
    # a plane array gives the same; NaN peaks pass through as NaN
    uv2 = uv.copy()
    uv2[0] = np.nan
    res2 = triangulate_peaks(uv2, CAM, TRUE_PLANE)
    assert np.isnan(res2.xyz[0]).all() and res2.n_invalid == 1
    assert np.array_equal(res2.xyz[1:], res.xyz[1:])


def test_distortion_matters():
    rng = np.random.default_rng(0)
    X = np.concatenate([line_on_target(board_pose(rng)) for _ in range(3)])
    pinhole = PinholeCamera(K=CAM.K, width=CAM.width, height=CAM.height, dist=np.zeros(5),
                            T_world_cam=CAM.T_world_cam)
    rms = {}
    for noise in (0.0, 0.05):
        uv, Xi = image_points(X, noise, rng)
        for cam in (CAM, pinhole):
            err = np.linalg.norm(triangulate_peaks(uv, cam, LASER).xyz - Xi, axis=1)
            rms[noise, cam is CAM] = np.sqrt(np.mean(err ** 2))
    assert rms[0.0, True] < 1e-9 and rms[0.0, False] > 5e-5   # lens ignored (as Horus does): ~0.1 mm
    assert rms[0.05, True] < 5e-5                              # 0.05 px noise: ~30 um
    assert rms[0.05, False] > 2.5 * rms[0.05, True]


def test_plane_through_camera_centre_is_config_error():
    bad = LineLaser(plane=laser_plane([1.0, 0.0, 0.0], CAM.center + [0.0005, 0, 0]), name="laser1")
    with pytest.raises(ConfigError, match=r"laser 'laser1'.*passes within 0\.500 mm.*every ray is parallel"):
        triangulate_peaks(np.array([[600.0, 500.0]]), CAM, bad)


def test_grazing_rays_are_refused():
    # The plane x_cam = 0.05 m contains the direction of the optical axis: rays near the principal
    # column are (nearly) parallel to it.
    n_world = CAM.T_world_cam[:3, 0]
    plane = laser_plane(n_world, CAM.center + 0.05 * n_world)
    cx = CAM.K[0, 2]
    uv = np.array([[cx, 300.0], [cx + 10.0, 500.0], [cx + 400.0, 500.0], [cx - 400.0, 500.0]])
    res = triangulate_peaks(uv, CAM, plane)
    assert np.isnan(res.xyz[:2]).all() and res.n_grazing == 2
    assert np.isfinite(res.xyz[2]).all() and res.n_behind == 1 and np.isnan(res.xyz[3]).all()
    assert abs(res.xyz[2] @ plane[:3] + plane[3]) < 1e-12
    assert np.degrees(res.angle[2]) > 2.0 and np.degrees(res.angle[1]) < 2.0


def test_to_turntable_frame_matches_table_motion():
    T = table_frame([0.1, 0.0, 1.0], [0.01, 0.02, 0.0])
    rng = np.random.default_rng(3)
    X0 = rng.normal(size=(50, 3)) * 0.05
    angles = rng.uniform(-np.pi, np.pi, 50)
    seen = np.stack([apply_T(table_motion(T, a), X0[i:i + 1])[0] for i, a in enumerate(angles)])
    assert np.max(np.abs(to_turntable_frame(seen, angles, T) - X0)) < 1e-14
    one = apply_T(table_motion(T, 0.7), X0)
    assert np.max(np.abs(to_turntable_frame(one, 0.7, T) - X0)) < 1e-14


# ------------------------------------------------------------------------------------------ plane fit
def test_fit_plane_robust_to_outliers():
    rng = np.random.default_rng(5)
    P = np.column_stack([rng.uniform(-0.1, 0.1, (500, 2)), rng.normal(scale=1e-5, size=500)])
    P[:150, 2] += rng.uniform(0.002, 0.02, 150)  # 30 % interreflections
    T = make_T(axis_angle_to_R([1.0, 2.0, 0.5], 0.7), [0.1, -0.2, 0.3])
    fit = fit_plane(apply_T(T, P))
    assert math.degrees(plane_errors(fit.plane, np.append(T[:3, 2], -T[:3, 2] @ T[:3, 3])).normal_angle) < 0.01
    assert fit.n_inliers >= 340 and not fit.inliers[:150].any()
    assert 0.5e-5 < fit.rms < 2e-5


def test_fit_plane_collinear_is_calibration_error():
    P = np.outer(np.linspace(0, 0.1, 50), [1.0, 2.0, 3.0])
    with pytest.raises(CalibrationError, match="collinear"):
        fit_plane(P, what="test set")


# ------------------------------------------------------------------------------------------ calibration
@pytest.mark.parametrize("noise, angle_deg, offset_mm", [(0.0, 1e-8, 1e-8), (0.05, 0.02, 0.02)])
def test_calibration_from_ten_poses(noise, angle_deg, offset_mm):
    cal = calibrate_laser_plane(CAM, views(10, noise), name="laser0")
    assert len(cal.used) == 10 and not cal.rejected
    e = plane_errors(cal.plane, TRUE_PLANE, cal.points)
    assert math.degrees(e.normal_angle) < angle_deg
    assert e.offset * 1e3 < offset_mm and e.max_deviation * 1e3 < max(offset_mm, 1e-8) * 2
    assert cal.plane[:3] @ CAM.center + cal.plane[3] > 0  # normal towards the camera
    laser = calibrated_laser(LineLaser(plane=[1.0, 0, 0, 0], name="laser0", switch=1, power=0.5), cal)
    assert laser.switch == 1 and laser.power == 0.5 and np.allclose(laser.plane, cal.plane)
    text = "\n".join(report_lines(cal, truth=LASER))
    assert "against the truth: normal" in text and "10 poses" in text


def test_pose_that_misses_the_board_is_rejected_by_name():
    vs = views(5, 0.05)
    rng = np.random.default_rng(9)
    # the board moved 0.25 m sideways: the sheet meets its plane, but outside the board
    T = compose(make_T(t=0.25 * TRUE_PLANE[:3]), board_pose(rng))
    uv, _ = image_points(line_on_target(T, clip=False))
    assert len(uv) > 100
    vs.insert(2, board_view(BOARD, uv, T, name="board pose 99"))
    vs.append(board_view(BOARD, np.zeros((0, 2)), T, name="board pose 100"))
    cal = calibrate_laser_plane(CAM, vs, name="laser0")
    rejected = dict(cal.rejected)
    assert set(rejected) == {"board pose 99", "board pose 100"}
    assert "misses the target: 0 of" in rejected["board pose 99"] and "no laser points" in rejected["board pose 100"]
    assert math.degrees(plane_errors(cal.plane, TRUE_PLANE).normal_angle) < 0.05
    assert any("rejected board pose 99" in line for line in report_lines(cal))


def test_two_poses_one_with_most_points_and_a_wrong_pose():
    # The points of one pose lie exactly in its board's plane: with two poses, one holding 80 % of the
    # points, a plain least-median fit would return that board's plane (60 degrees off). Per-pose scoring
    # does not.
    rng = np.random.default_rng(11)
    vs = []
    for i, step in enumerate((1e-4, 4e-4)):
        T = board_pose(rng)
        uv, _ = image_points(line_on_target(T, step=step), 0.2, rng)
        vs.append(board_view(BOARD, uv, T, name=f"board pose {i + 1}"))
    cal = calibrate_laser_plane(CAM, vs, name="laser0")
    assert math.degrees(plane_errors(cal.plane, TRUE_PLANE).normal_angle) < 0.1 and cal.fit.rms > 1e-5
    # a pose whose board pose is 2 mm off along its normal: its points are outliers, named in the report
    vs = views(8, 0.05)
    T = vs[3].T_world_target
    vs[3] = board_view(BOARD, vs[3].points_uv, compose(T, make_T(t=[0.0, 0.0, 0.002])), name="board pose 4")
    cal = calibrate_laser_plane(CAM, vs, name="laser0")
    assert cal.views[3].n_inliers < 0.1 * cal.views[3].n_on_target
    assert math.degrees(plane_errors(cal.plane, TRUE_PLANE).normal_angle) < 0.02
    assert any(line.startswith("  board pose 4:") and "off the plane" in line for line in report_lines(cal))


def test_collinear_poses_are_calibration_error():
    rng = np.random.default_rng(2)
    T0 = board_pose(rng)
    vs = []
    for i, s in enumerate(np.linspace(-0.02, 0.02, 5)):   # the board slides within its own plane
        T = compose(T0, make_T(t=[s, 0.5 * s, 0.0]))
        uv, _ = image_points(line_on_target(T), 0.05, rng)
        vs.append(board_view(BOARD, uv, T, name=f"board pose {i + 1}"))
    with pytest.raises(CalibrationError, match=r"laser 'laser0'.*collinear"):
        calibrate_laser_plane(CAM, vs, name="laser0")
    with pytest.raises(CalibrationError, match="collinear"):
        calibrate_laser_plane(CAM, vs[:1], name="laser0")


def test_parallel_lines_do_fix_the_plane():
    # The board moved along its normal: parallel but distinct lines span the plane.
    rng = np.random.default_rng(4)
    T0 = board_pose(rng, tilt_deg=0.0, shift=0.0)
    vs = []
    for i, s in enumerate((-0.03, 0.0, 0.03)):
        T = compose(T0, make_T(t=[0.0, 0.0, s]))
        uv, _ = image_points(line_on_target(T))
        vs.append(board_view(BOARD, uv, T, name=f"board pose {i + 1}"))
    cal = calibrate_laser_plane(CAM, vs)
    assert math.degrees(plane_errors(cal.plane, TRUE_PLANE).normal_angle) < 1e-8


def test_board_pose_from_camera_and_plate_view():
    rng = np.random.default_rng(6)
    vs = views(4, 0.0)
    T_world_board = vs[0].T_world_target
    again = board_view(BOARD, vs[0].points_uv, T_cam_board=compose(invert_T(CAM.T_world_cam), T_world_board),
                       camera=CAM, name="board pose 1")
    assert np.allclose(again.T_world_target, T_world_board, atol=1e-15)
    plate = line_on_target(RIG.T_world_table, extent=(-0.15, -0.15, 0.15, 0.15))
    plate = plate[np.hypot(plate[:, 0], plate[:, 1]) < 0.15]
    uv, _ = image_points(plate, 0.0, rng)
    cal = calibrate_laser_plane(CAM, vs + [plate_view(RIG.T_world_table, uv)], name="laser0")
    assert "turntable plate" in cal.used and cal.views[-1].n_on_target == len(uv)
    assert math.degrees(plane_errors(cal.plane, TRUE_PLANE).normal_angle) < 1e-8
    # the plate alone is one line
    with pytest.raises(CalibrationError, match="collinear"):
        calibrate_laser_plane(CAM, [plate_view(RIG.T_world_table, uv)])


def test_bad_input_is_named():
    from rangekit.errors import InputError
    with pytest.raises(InputError, match=r"points_uv must be an \(N, 2\).*found shape \(3,\)"):
        triangulate_peaks(np.zeros(3), CAM, LASER)
    with pytest.raises(InputError, match="laser plane: must be a LineLaser or 4 finite numbers"):
        triangulate_peaks(np.zeros((1, 2)), CAM, [0.0, 0.0, 0.0, 1.0])
    T = np.eye(4)
    with pytest.raises(InputError, match="board pose 7: give the board's pose as T_world_board or as T_cam_board"):
        board_view(BOARD, np.zeros((0, 2)), T, T_cam_board=T, camera=CAM, name="board pose 7")
    with pytest.raises(InputError, match=r"turntable plate: the laser points must be an \(N, 2\)"):
        plate_view(T, np.zeros((4, 3)))
    with pytest.raises(CalibrationError, match="laser 'laser1': no target poses"):
        calibrate_laser_plane(CAM, [], name="laser1")
    with pytest.raises(CalibrationError, match=r"laser 'laser1': no usable target pose \(rejected: board pose 1: no "
                                               "laser points"):
        calibrate_laser_plane(CAM, [board_view(BOARD, np.zeros((0, 2)), T, name="board pose 1")], name="laser1")
