"""Laser-plane calibration on hardware (``rangekit calibrate --lasers --rig RIG.json``),
driven here with simulated devices: a SimRig (light="laser") whose scene is the board the test's ``ask``
places at known poses, a rig file whose laser planes are rough guesses; the fitted planes against the
simulator's true ones, the laser commands, a pose missing a line, an interrupted run, refusals."""

import builtins
import json
import math
import sys
from dataclasses import replace

import numpy as np
import pytest

import rangekit.drivers
from rangekit.app.laser.calibration_hw import calibrate_lasers_on_devices
from rangekit.boards import Board
from rangekit.cli import main
from rangekit.errors import ConfigError
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.laser.plane_calib import plane_errors
from rangekit.rig.lasers import laser_plane
from rangekit.rig.rig_file import load_rig, save_rig, template_rig
from rangekit.sim.writers.calibration import board_scene, pose_problem
from rangekit.sim.devices.sim_rig import SimRig
from rangekit.sim.laser.board import laser_board_poses, line_on_board
from rangekit.sim.laser.rig import laser_rig

BOARD = Board()
DEVICES = {"camera": {"type": "depthai", "id": None, "socket": "CAM_A"},
           "turntable": {"protocol": "horus", "port": "/dev/ttyUSB0", "baud": 115200}}


@pytest.fixture(scope="module")
def truth():
    return laser_rig()


def _rough(truth):
    """The rig file a user has: the true (calibrated) camera, hardware devices, switches 1 and 2, and laser
    planes guessed 3 deg and 5 mm off."""
    lasers = []
    for laser in truth.lasers:
        n = axis_angle_to_R([1.0, 0.0, 0.0], math.radians(3.0)) @ laser.normal
        lasers.append(replace(laser, plane=laser_plane(n, laser.origin + 0.005 * n), origin=None))
    return replace(truth, lasers=tuple(lasers), devices=DEVICES)


class _Board:
    """The simulated turntable's laser switch, recording every command and never two lasers on."""

    def __init__(self, table, log):
        self._table, self.log = table, log

    def laser(self, n, on):
        self.log.append((n, bool(on)))
        self._table.laser(n, on)
        assert len(self._table.lasers_on) <= 1


class _Devices:
    def __init__(self, sim, log):
        self.sim, self.camera, self.turntable = sim, sim.camera, _Board(sim.turntable, log)
        self.closed = False

    def close(self):
        self.closed = True


def _devices(truth, poses, log, *, interrupt_at=None):
    """(devices, ask): ``ask`` places the board at the next pose (KeyboardInterrupt at ``interrupt_at``)."""
    sim = SimRig(board_scene(BOARD, poses[0]), truth, light="laser", seed=7, laser_ambient_scale=2)
    prompts = []

    def ask(prompt):
        if len(prompts) == interrupt_at:
            raise KeyboardInterrupt
        sim.set_scene(board_scene(BOARD, poses[len(prompts)]))
        prompts.append(prompt)

    return _Devices(sim, log), ask, prompts


def _fronto(truth, x, y, z=0.05, roll_deg=0.0):
    R = truth.camera.T_world_cam[:3, :3] @ axis_angle_to_R([0, 0, 1.0], math.radians(roll_deg))
    x0, y0, x1, y1 = BOARD.extent
    return make_T(R, np.array([x, y, z]) - R @ np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0]))


def _write_rig(tmp_path, rig):
    path = tmp_path / "rig.json"
    save_rig(rig, path)
    return path


@pytest.fixture
def tty(monkeypatch):
    """A terminal on standard input, as ``rangekit calibrate`` on hardware needs."""
    monkeypatch.setattr(sys, "stdin", type("Tty", (), {"isatty": lambda self: True})())


def test_cli_fits_the_true_planes_from_ten_placed_poses(truth, tmp_path, monkeypatch, capsys, tty):
    """Acceptance on hardware's code path: 10 board poses placed by ``ask``, the board pose by PnP with the
    rig file's camera; each plane within 0.02 deg and 0.02 mm of the truth (measured: docs/laser.md), the
    lasers switched one at a time and all off at the end, the rig file otherwise unchanged."""
    rough = _rough(truth)
    poses = laser_board_poses(truth, BOARD, 10, seed=0)
    log = []
    devices, ask, prompts = _devices(truth, poses, log)
    monkeypatch.setattr(rangekit.drivers, "open_rig_devices", lambda rig, **kw: devices)
    monkeypatch.setattr(builtins, "input", ask)
    rig_file, out = _write_rig(tmp_path, rough), tmp_path / "rig2.json"
    assert main(["calibrate", "--lasers", "--rig", str(rig_file), "--out", str(out), "--laser-poses", "10"]) == 0
    text = capsys.readouterr().out
    assert len(prompts) == 10 and prompts[0].startswith("laser pose 1/10: hold the 10x7 board still")
    assert devices.closed
    # commands: all off, then per pose laser 1 on/off, laser 2 on/off, then all off again
    assert log == [(1, False), (2, False)] + [(1, True), (1, False), (2, True), (2, False)] * 10 + \
        [(1, False), (2, False)]
    assert devices.sim.turntable.lasers_on == set()
    got = load_rig(out)
    for fitted, true in zip(got.lasers, truth.lasers):
        err = plane_errors(fitted.plane, true.plane)
        assert math.degrees(err.normal_angle) < 0.02 and err.offset < 0.02e-3, (fitted.name, err)
        assert fitted.switch == true.switch and fitted.name == true.name
    a, b = got.to_dict(), rough.to_dict()
    assert [la["plane"] for la in a.pop("lasers")] != [la["plane"] for la in b.pop("lasers")]
    assert json.dumps(a) == json.dumps(b)                      # everything else as it was
    assert "== calibration ==" not in text and text.count(": plane n = [") == 2 and text.count("RMS residual") == 2
    assert "rejected" not in text


def test_a_pose_whose_line_misses_the_board_is_rejected_by_name(truth):
    miss = _fronto(truth, 0.12, 0.10, roll_deg=90)
    assert pose_problem(truth.camera, BOARD, miss) == "" and line_on_board(BOARD, miss, truth.lasers[0].plane) == 0
    poses = laser_board_poses(truth, BOARD, 4, seed=5)
    poses.insert(2, miss)
    log = []
    devices, ask, _ = _devices(truth, poses, log)
    res = calibrate_lasers_on_devices(devices, _rough(truth), n_poses=5, ask=ask)
    assert [name for name, _ in res.lasers[0].rejected] == ["board pose 3"]
    assert any(r.startswith("laser0: board pose 3:") for r in res.rejected)
    assert "board pose 3" in res.lasers[1].used
    assert any("rejected board pose 3" in line for line in res.summary_lines())
    err = plane_errors(res.rig.lasers[0].plane, truth.lasers[0].plane)
    assert math.degrees(err.normal_angle) < 0.02 and err.offset < 0.02e-3


def test_an_interrupted_run_leaves_the_lasers_off_and_writes_no_rig(truth, tmp_path, monkeypatch, tty):
    poses = laser_board_poses(truth, BOARD, 3, seed=1)
    log = []
    devices, ask, _ = _devices(truth, poses, log, interrupt_at=2)
    monkeypatch.setattr(rangekit.drivers, "open_rig_devices", lambda rig, **kw: devices)
    monkeypatch.setattr(builtins, "input", ask)
    rig_file, out = _write_rig(tmp_path, _rough(truth)), tmp_path / "rig2.json"
    assert main(["calibrate", "--lasers", "--rig", str(rig_file), "--out", str(out)]) == 130
    assert not out.exists() and devices.closed
    assert log[-2:] == [(1, False), (2, False)] and devices.sim.turntable.lasers_on == set()
    assert log.count((1, True)) == 2                            # two poses captured before the interrupt


def test_a_camera_fault_mid_pose_switches_every_laser_off(truth):
    poses = laser_board_poses(truth, BOARD, 2, seed=1)
    log = []
    devices, ask, _ = _devices(truth, poses, log)
    devices.sim.inject_fault("camera", after=2)                  # pose 1: off, laser 1, then laser 2 fails
    with pytest.raises(Exception, match="unplugged"):
        calibrate_lasers_on_devices(devices, _rough(truth), n_poses=2, ask=ask)
    assert log[-4:] == [(2, True), (2, False), (1, False), (2, False)]
    assert devices.sim.turntable.lasers_on == set()


@pytest.mark.parametrize("change, message", [
    (lambda r: replace(r, lasers=()), r"lasers: expected a list.*docs/rig\.md"),
    (lambda r: replace(r, cameras=(replace(r.camera, K=np.array(template_rig()["cameras"][0]["K"]),
                                           dist=np.zeros(5)),)), r"cameras\[0\].*placeholder.*calibrate it first"),
    (lambda r: replace(r, devices={"camera": DEVICES["camera"]}), r"devices\.turntable: expected the turntable"),
])
def test_an_unusable_rig_is_refused_before_anything_moves(truth, tmp_path, monkeypatch, capsys, tty, change,
                                                          message):
    def never(*args, **kw):
        raise AssertionError("a device was opened")

    monkeypatch.setattr(rangekit.drivers, "open_rig_devices", never)
    monkeypatch.setattr(builtins, "input", never)
    rig_file, out = _write_rig(tmp_path, change(_rough(truth))), tmp_path / "rig2.json"
    assert main(["calibrate", "--lasers", "--rig", str(rig_file), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert str(rig_file) in err and __import__("re").search(message, err) and not out.exists()


def test_devices_without_a_laser_switch_are_refused(truth):
    class NoSwitch:
        camera, turntable = object(), object()

    with pytest.raises(ConfigError, match="turntable board with laser switches"):
        calibrate_lasers_on_devices(NoSwitch(), _rough(truth), n_poses=2, ask=lambda p: None)


def test_camera_calibration_of_a_rig_without_projector_is_refused(truth, tmp_path, monkeypatch, capsys, tty):
    """A Ciclop rig file (no projector): plain ``rangekit calibrate`` needs the projector's coded light and
    says so (exit 1, naming the field), before any device is opened."""
    def never(*args, **kw):
        raise AssertionError("a device was opened")

    monkeypatch.setattr(rangekit.drivers, "open_rig_devices", never)
    rig_file, out = _write_rig(tmp_path, replace(_rough(truth), projector=None)), tmp_path / "rig2.json"
    assert main(["calibrate", "--rig", str(rig_file), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "devices.projector.display" in err and "--lasers" in err and not out.exists()
