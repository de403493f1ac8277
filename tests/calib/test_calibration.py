"""Calibration against the simulator's exact rig.

One module fixture runs the whole simulated calibration (8-bit captures, ~1% noise, lens and projector
blur, projector gamma 2.2): 20 hand-held board poses plus one pose where the board is out of view, then
9 turntable angles. Every figure is compared with :func:`rangekit.sim.devices.sim_rig.default_rig`, the truth.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from rangekit.boards import Board
from rangekit.calib.camera import CalibrationWarning, Correspondences, calibrate_device
from rangekit.calib.procedure import CalibrationSettings, calibrate_rig, compare_rigs
from rangekit.errors import CalibrationError
from support.calib_tolerances import outside_tolerances
from support.fits import fit_sphere
from rangekit.geometry import apply_T, make_T

pytestmark = pytest.mark.filterwarnings("ignore::rangekit.calib.camera.CalibrationWarning")


@pytest.fixture(scope="module")
def calibrated():
    from rangekit.sim.writers.calibration import board_poses, board_scene, turntable_board_scene
    from rangekit.sim.devices.sim_rig import SimRig, default_rig

    truth = default_rig()
    board = Board()
    poses = board_poses(truth, board, 20, seed=0)
    lost = make_T(t=np.array([0.2, 0.0, 0.0])) @ poses[3]        # mostly out of view: no board found
    poses = poses[:3] + [lost] + poses[3:]
    sim = SimRig(board_scene(board, poses[0]), seed=0)
    messages = []

    def place(i, n):
        sim.set_scene(board_scene(board, poses[i]))

    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        result = calibrate_rig(sim, settings=CalibrationSettings(board=board, n_poses=len(poses)), place_board=place,
                               place_on_turntable=lambda: sim.set_scene(turntable_board_scene(truth, board)),
                               template=truth, progress=lambda msg, *a, **k: messages.append(msg))
    return truth, result, compare_rigs(result.rig, truth), messages


@pytest.mark.slow
def test_reprojection_errors(calibrated):
    _, res, _, _ = calibrated
    assert res.bundle.rms_camera <= 0.1, res.summary_lines()
    assert res.bundle.rms_projector <= 0.15, res.summary_lines()
    # Measured 0.026 and 0.021 px: a corner bias of a tenth of a pixel would show.
    assert res.bundle.rms_camera <= 0.04 and res.bundle.rms_projector <= 0.04


@pytest.mark.slow
def test_every_parameter_is_within_the_shared_tolerances(calibrated):
    _, _, dev, _ = calibrated
    assert outside_tolerances(dev) == []


@pytest.mark.slow
def test_intrinsics_match_truth(calibrated):
    _, _, dev, _ = calibrated
    for key in ("fx", "fy", "cx", "cy"):
        assert abs(dev["camera"][key]) <= 0.2, (key, dev["camera"])
        assert abs(dev["projector"][key]) <= 0.3, (key, dev["projector"])
    # Distortion: k1 and k2 of both devices close to the truth (measured within 0.0003 and 0.0025).
    assert abs(dev["camera"]["dist_diff"][0]) < 0.002 and abs(dev["projector"]["dist_diff"][0]) < 0.002


@pytest.mark.slow
def test_extrinsics_match_truth(calibrated):
    _, _, dev, _ = calibrated
    assert abs(dev["baseline_pct"]) <= 0.1, dev
    assert dev["rotation_deg"] <= 0.02, dev


@pytest.mark.slow
def test_turntable_axis_matches_truth(calibrated):
    _, res, dev, _ = calibrated
    assert dev["axis_direction_deg"] <= 0.05, dev
    assert dev["axis_point_mm"] <= 0.2, dev
    assert dev["table_origin_mm"] <= 0.5, dev          # includes the table-top height along the axis
    assert abs(res.axis.angle_scale - 1.0) < 1e-3


@pytest.mark.slow
def test_projector_response_matches_truth(calibrated):
    _, _, dev, _ = calibrated
    assert abs(dev["gamma"]) < 0.02, dev


@pytest.mark.slow
def test_missing_board_view_is_skipped_and_named(calibrated):
    _, res, _, messages = calibrated
    view = res.camera.views[3]
    assert not view.used and view.name == "pose 4" and "not found" in view.reason
    assert len(res.camera.used) == 20
    assert any("pose 4" in line and "rejected" in line for line in res.summary_lines())
    assert any("board pose" in m for m in messages)


@pytest.mark.slow
def test_calibrated_rig_has_the_simulator_schema(calibrated):
    truth, res, _, _ = calibrated
    a, b = res.rig.to_dict(), truth.to_dict()
    assert list(a) == list(b)
    assert list(a["cameras"][0]) == list(b["cameras"][0])
    # Same world frame (the turntable's): the camera poses agree to a fraction of a millimetre.
    assert np.abs(np.asarray(a["cameras"][0]["T_world_cam"]) - np.asarray(b["cameras"][0]["T_world_cam"])).max() < 1e-3


@pytest.mark.slow
def test_round_trip_sphere_radius_with_the_calibrated_rig(calibrated):
    """Scan a sphere in the simulator (true rig) and reconstruct with the calibrated rig."""
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.sim.devices.sim_rig import SimRig
    from rangekit.sim.scene.objects import make_object
    from rangekit.sim.scene.scene import Scene

    truth, res, _, _ = calibrated
    radius = 0.05
    sphere = make_object("sphere", radius=radius).with_pose(make_T(t=np.array([0.0, 0.0, 0.06])))
    sim = SimRig(Scene((sphere,)), truth, seed=3)
    spec = make_pattern_spec("hybrid", truth.projector.size)
    images = sim.capture_sequence(list(spec.frames()))
    rec = reconstruct_view(images, spec, res.rig.camera, res.rig.projector, response=res.rig.projector_response)
    pts = rec.triangulated.xyz.reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    assert len(pts) > 50000
    _, r_cal = fit_sphere(pts)
    gt = sim.ground_truth()
    _, r_true = fit_sphere(gt.xyz[gt.lit])
    assert abs(r_cal - r_true) <= 0.2e-3, (r_cal, r_true)
    assert abs(r_cal - radius) <= 0.2e-3, (r_cal, radius)


# ----------------------------------------------------------------------------- bad input, synthetic corners
def _synthetic_views(n: int, *, seed: int = 0, parallel: bool = False):
    from rangekit.sim.writers.calibration import board_poses
    from rangekit.sim.devices.sim_rig import default_rig

    truth = default_rig()
    board = Board()
    obj = board.object_points()
    poses = board_poses(truth, board, n, seed=seed)
    if parallel:  # every pose with the first one's orientation, only moved sideways
        poses = [make_T(poses[0][:3, :3], poses[0][:3, 3] + np.array([0.01 * k, 0.005 * k, 0.0])) for k in range(n)]
    rng = np.random.default_rng(seed)
    views = []
    for T in poses:
        uv = truth.camera.project(apply_T(T, obj)) + rng.normal(0, 0.03, (len(obj), 2))
        views.append(Correspondences(np.arange(len(obj)), uv))
    return views, obj, truth.camera


def test_synthetic_calibration_recovers_the_camera():
    views, obj, cam = _synthetic_views(12)
    cal = calibrate_device(views, obj, cam.size)
    assert cal.rms < 0.06
    assert abs(cal.device.K[0, 0] / cam.K[0, 0] - 1) < 1e-3


def test_missing_views_are_skipped_with_reason():
    views, obj, cam = _synthetic_views(8)
    views[2] = None
    views[5] = Correspondences(np.arange(4), views[5].uv[:4])
    cal = calibrate_device(views, obj, cam.size, names=[f"img{i}.png" for i in range(8)])
    rejected = {v.name: v.reason for v in cal.views if not v.used}
    assert set(rejected) == {"img2.png", "img5.png"}
    assert "not found" in rejected["img2.png"] and "only 4 corners" in rejected["img5.png"]


def test_fewer_than_three_usable_views_is_an_error_naming_them():
    views, obj, cam = _synthetic_views(4)
    views[0] = None
    views[1] = Correspondences(np.zeros(0, np.int64), np.zeros((0, 2)), "board not found")
    with pytest.raises(CalibrationError, match=r"only 2 usable view\(s\) of 4.*view_000.*view_001"):
        calibrate_device(views, obj, cam.size)


def test_nearly_parallel_poses_are_detected():
    views, obj, cam = _synthetic_views(6, parallel=True)
    with pytest.raises(CalibrationError, match="nearly parallel"):
        calibrate_device(views, obj, cam.size)


def test_a_misdetected_view_is_rejected_with_its_rms():
    views, obj, cam = _synthetic_views(10, seed=2)
    bad = views[4].uv.copy()
    bad[::3] += 2.0                       # a third of the corners 2 px off: a misdetection
    views[4] = Correspondences(views[4].ids, bad)
    with pytest.warns(CalibrationWarning, match="view_004 rejected"):
        cal = calibrate_device(views, obj, cam.size)
    assert not cal.views[4].used and "reprojection RMS" in cal.views[4].reason
    assert cal.rms < 0.06


# ----------------------------------------------------------------------------- depthai conversion
def test_depthai_converted_rig_triangulates_in_the_simulator(tmp_path):
    """The simulator's camera stored as a depthai calibration (EEPROM JSON), converted back with
    calibration_to_rig, triangulates a simulated scan as well as the true rig does."""
    dai = pytest.importorskip("depthai")
    from rangekit.drivers.depthai.camera import calibration_to_rig
    from rangekit.geometry import invert_T
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.sim import SimRig, default_scene
    from rangekit.sim.devices.sim_rig import default_rig

    truth = default_rig()
    cam = truth.camera
    S = dai.CameraBoardSocket
    h = dai.CalibrationHandler()
    h.setCameraIntrinsics(S.CAM_A, cam.K.tolist(), dai.Size2f(cam.width, cam.height))
    h.setCameraType(S.CAM_A, dai.CameraModel.Perspective)
    h.setDistortionCoefficients(S.CAM_A, list(cam.dist) + [0.0] * (14 - len(cam.dist)))
    path = tmp_path / "calib.json"
    assert h.eepromToJsonFile(str(path))
    converted = calibration_to_rig(dai.CalibrationHandler(str(path)), size=cam.size, device_id="sim")
    # World = the depthai camera's frame; the projector's pose is known relative to it.
    T_cam_world = cam.T_cam_world
    projector = truth.projector.with_pose(T_cam_world @ truth.projector.T_world_cam)
    sim = SimRig(default_scene("sphere"), truth, seed=5)
    spec = make_pattern_spec("hybrid", truth.projector.size)
    images = sim.capture_sequence(list(spec.frames()))
    rec = reconstruct_view(images, spec, converted.camera, projector, response=truth.projector_response)
    xyz = rec.triangulated.xyz
    gt = sim.ground_truth()
    ok = np.isfinite(xyz[:, :, 0]) & gt.lit & (gt.object_id == gt.object_names.index("sphere"))
    assert ok.sum() > 50000
    X_true = apply_T(T_cam_world, gt.xyz[ok])
    err = np.linalg.norm(xyz[ok] - X_true, axis=1)
    # Same figures as with the true rig: decoding noise only (a wrong focal length or a dropped distortion
    # coefficient would give millimetres at the image borders).
    print("depthai-converted rig: median %.2e m, p95 %.2e m" % (np.median(err), np.percentile(err, 95)))
    assert np.median(err) < 0.03e-3 and np.percentile(err, 95) < 0.15e-3, (np.median(err), np.percentile(err, 95))
    assert np.allclose(converted.camera.K, cam.K, rtol=1e-6) and np.allclose(invert_T(np.eye(4)), converted.camera.T_world_cam)


# ----------------------------------------------------------------------------- command line
def test_calibrate_command_refuses_bad_input_before_any_work(tmp_path, capsys):
    from rangekit.cli import main

    existing = tmp_path / "rig.json"
    existing.write_text("{}")
    assert main(["calibrate", "--out", str(existing)]) == 2
    assert "exists; choose another file, or pass --force" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["calibrate", "--out", str(tmp_path / "new.json"), "--poses", "2"])
    assert stop.value.code == 2
    assert "--poses: expected an integer in 3..200, found '2'" in capsys.readouterr().err
    bad = tmp_path / "bad_rig.json"
    bad.write_text('{"schema": "rangekit.rig/1", "cameras": []}')
    assert main(["calibrate", "--rig", str(bad), "--out", str(tmp_path / "out.json")]) == 1
    assert "cameras" in capsys.readouterr().err
    assert not (tmp_path / "new.json").exists() and not (tmp_path / "out.json").exists()
