"""Calibration with feedback: each board pose is judged as it is captured, against the
simulator's truth: good poses reproject well under 0.5 px, bad poses (out of view, too oblique, too small)
are rejected with the reason named, and the summary counts the kept poses."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from rangekit.boards import Board
from rangekit.calib.pose_feedback import FeedbackLimits, check_pose, coverage_grid, coverage_image
from rangekit.geometry import axis_angle_to_R, compose, make_T

pytestmark = pytest.mark.filterwarnings("ignore::rangekit.calib.camera.CalibrationWarning")


def _facing(cam, board: Board, distance: float, tilt_deg: float) -> np.ndarray:
    """T_world_board: the board's centre on the optical axis at ``distance`` m, tilted about its x axis."""
    x0, y0, x1, y1 = board.extent
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    R = axis_angle_to_R([1.0, 0.0, 0.0], np.radians(tilt_deg))
    return compose(cam.T_world_cam, make_T(R, np.array([0.0, 0.0, distance]) - R @ c))


def _small_rig():
    """The simulator's default rig on a 480 x 384 camera and a 480 x 300 projector (same lenses): fast."""
    import dataclasses

    from rangekit.sim.devices.sim_rig import default_rig

    t = default_rig()
    return dataclasses.replace(t, cameras=(t.camera.resized(480, 384),), projector=t.projector.resized(480, 300))


@pytest.fixture(scope="module")
def sim_setup():
    from rangekit.sim.writers.calibration import board_poses, board_scene
    from rangekit.sim.devices.sim_rig import SimRig

    truth = _small_rig()
    board = Board()
    good = board_poses(truth, board, 5, seed=3)
    bad = {"board not found": make_T(t=np.array([0.25, 0.0, 0.0])) @ good[1],
           "too oblique": _facing(truth.camera, board, 0.4, 70.0),
           "too small": _facing(truth.camera, board, 1.5, 10.0)}
    sim = SimRig(board_scene(board, good[0]), truth, seed=1)
    sim.turntable = None
    return truth, board, good, bad, sim


@pytest.fixture(scope="module")
def calibrated(sim_setup, tmp_path_factory):
    """calibrate_rig on 5 good and 3 bad simulated poses, no terminal (every rejected pose skipped)."""
    from rangekit.calib.procedure import CalibrationSettings, calibrate_rig
    from rangekit.io import write_png
    from rangekit.sim.writers.calibration import board_scene

    truth, board, good, bad, sim = sim_setup
    poses = good[:2] + [bad["board not found"]] + good[2:4] + [bad["too oblique"]] + good[4:] + [bad["too small"]]
    lines, asked = [], []
    png = tmp_path_factory.mktemp("feedback") / "coverage.png"

    def on_pose(check, coverage):
        write_png(png, coverage)
        lines.append(check.line())
        asked.append(check.index)
        return False                      # no terminal: skip and count

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate_rig(sim, settings=CalibrationSettings(board=board, n_poses=len(poses), measure_response=False,
                                                              patterns="graycode"),
                            place_board=lambda i, n: sim.set_scene(board_scene(board, poses[i])), template=truth,
                            on_pose=on_pose)
    return truth, res, lines, asked, png


def test_good_poses_reproject_under_half_a_pixel(calibrated):
    truth, res, lines, asked, png = calibrated
    kept = [c for c in res.pose_checks if c.accepted]
    assert len(kept) == 5
    assert all(c.reprojection_px < 0.5 for c in kept), [c.reprojection_px for c in kept]
    assert kept[0].fit == "single-pose fit" and "3 kept poses" in kept[3].fit
    # the coverage grows with the kept poses and is never above 1
    assert 0 < kept[0].coverage < kept[-1].coverage <= 1.0
    assert abs(res.rig.camera.K[0, 0] / truth.camera.K[0, 0] - 1) < 0.01


def test_bad_poses_are_rejected_naming_the_reason(calibrated):
    truth, res, lines, asked, png = calibrated
    rejected = {c.index: c for c in res.pose_checks if not c.accepted}
    assert sorted(rejected) == [2, 5, 7]
    assert rejected[2].reason == "board not found"
    assert rejected[5].reason.startswith("too oblique") and abs(rejected[5].tilt_deg - 70.0) < 2.0
    assert rejected[7].reason.startswith("too small in the image")
    assert lines[2] == "pose 3: rejected: board not found"
    assert lines[5].startswith("pose 6: rejected: too oblique")


def test_the_summary_counts_kept_poses_and_coverage_is_written(calibrated):
    from rangekit.io import read_png

    truth, res, lines, asked, png = calibrated
    assert asked == list(range(8))
    summary = res.summary_lines()
    assert summary[0] == "board poses: 5 of 8 kept (3 skipped, 0 retaken)"
    assert any("pose 8: rejected: too small" in s for s in summary)
    assert res.camera.used == [0, 1, 3, 4, 6]
    img = read_png(png)
    assert img.shape == (384, 480, 3)
    assert (img[..., 1] > 100).any()                  # covered cells are green


def test_too_few_corners_and_reprojection_limit():
    board = Board()
    from rangekit.boards import BoardDetection

    obj = board.object_points()
    R = axis_angle_to_R([1.0, 0.0, 0.0], np.radians(30.0))          # an exact pinhole view, tilted 30 deg
    xyz = obj @ R.T + np.array([-0.08, -0.05, 0.5])
    uv = (xyz[:, :2] / xyz[:, 2:]) * 1000.0 + [319.5, 239.5]
    det = BoardDetection(np.arange(len(obj)), uv, (640, 480))
    exact = check_pose(0, det, board, (640, 480))
    assert exact.accepted and exact.reprojection_px < 1e-3
    few = BoardDetection(np.arange(8), uv[:8], (640, 480))
    assert check_pose(0, few, board, (640, 480)).reason.startswith("too few corners: 8")
    noisy = BoardDetection(np.arange(len(obj)), uv + np.random.default_rng(0).normal(0, 2.0, uv.shape), (640, 480))
    c = check_pose(0, noisy, board, (640, 480), limits=FeedbackLimits(max_reprojection_px=1.0))
    assert c.reason.startswith("reprojection error") and c.reprojection_px > 1.0
    grid = coverage_grid([(det.ids, det.uv)], (640, 480))
    img = coverage_image([(det.ids, det.uv)], (640, 480), uv, True)
    assert grid.max() == 1 and img.shape == (480, 640, 3) and img.dtype == np.uint8


def test_a_rejected_pose_is_retaken_when_asked(sim_setup):
    from rangekit.calib.procedure import CalibrationSettings, calibrate_rig
    from rangekit.sim.writers.calibration import board_scene

    truth, board, good, bad, sim = sim_setup
    placed = []
    attempts = {"n": 0}

    def place(i, n):
        # pose 2 is out of view the first time, then the person moves it into view
        placed.append(i)
        T = bad["board not found"] if i == 1 and placed.count(1) == 1 else good[i]
        sim.set_scene(board_scene(board, T))

    def on_pose(check, coverage):
        attempts["n"] += 1
        return not check.accepted

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate_rig(sim, settings=CalibrationSettings(board=board, n_poses=3, measure_response=False,
                                                              patterns="graycode"),
                            place_board=place, template=truth, on_pose=on_pose)
    assert res.retaken == 1 and attempts["n"] == 4
    assert all(c.accepted for c in res.pose_checks)
    assert res.summary_lines()[0] == "board poses: 3 of 3 kept (0 skipped, 1 retaken)"
