"""The laser scan's acquisition through the real turntable drivers on the simulated Horus and FabScan
firmware over a pty, its resume after an unplug, and its bad input.

The simulated camera renders the lasers the *firmware* has on: a small wrapper (:class:`_DrivenBoard`)
sends every move and laser command through the driver, then mirrors the firmware's laser state
(``fw.lasers``) and the driver's angle into the simulated turntable. A wrong command order therefore
gives wrong frames (or two lasers on, which the simulator refuses).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rangekit.app.acquire.acquire import acquire
from rangekit.errors import DeviceError
from rangekit.formats.sessions.session import ScanPlan, load_session
from rangekit.laser.sequence import LaserSequence
from rangekit.sim import SimRig, default_scene
from rangekit.sim.laser.rig import laser_rig

N_STEPS = 8                      # 45 degree steps: whole microsteps, exact in the board's 3-decimal reports
MICROSTEP_DEG = 360.0 / 3200


def small_rig():
    rig = laser_rig()
    return replace(rig, cameras=(rig.camera.resized(320, 256),))


def sim(obj="lumpy", rig=None, **kw):
    return SimRig(default_scene(obj), rig or small_rig(), seed=0, light="laser", **kw)


def pngs(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.glob("view_*/*.png"))
            if not p.parent.name.endswith(".partial")}


class _DrivenBoard:
    """A real turntable driver on the simulated firmware; the simulator follows the board: its angle is
    the driver's, its lasers are those the firmware has on (``dead``: switch numbers whose light never
    reaches the scene). ``unplug_before``: (kind, n) unplugs the board before the n-th (0-based) "move" or
    "laser" call. ``log`` receives every firmware command line as it is executed."""

    def __init__(self, driver, fw, sim_turntable, log, *, dead=(), unplug_before=None):
        self.driver, self.fw, self.sim, self.log = driver, fw, sim_turntable, log
        self.dead, self.unplug_before = set(dead), unplug_before
        self.calls = {"move": 0, "laser": 0}
        self._seen = len(fw.lines)

    def _call(self, kind):
        if self.unplug_before == (kind, self.calls[kind]):
            self.fw.inject("unplug")
        self.calls[kind] += 1

    def _mirror(self):
        self.log.extend(self.fw.lines[self._seen:])
        self._seen = len(self.fw.lines)
        self.sim.lasers_on.clear()
        self.sim.lasers_on.update(n for n, on in self.fw.lasers.items() if on and n not in self.dead)

    @property
    def angle(self):
        return self.driver.angle

    def rotate_to(self, angle):
        self._call("move")
        self.driver.rotate_to(angle)
        self._mirror()
        self.sim.rotate_to(self.driver.angle)

    def laser(self, n, on):
        self._call("laser")
        self.driver.laser(n, on)
        self._mirror()


class _LoggedCamera:
    def __init__(self, camera, log):
        self.camera, self.log = camera, log

    @property
    def calibration(self):
        return self.camera.calibration

    def capture(self):
        self.log.append("capture")
        return self.camera.capture()


class _Devices:
    def __init__(self, camera, turntable):
        self.camera, self.projector, self.turntable = camera, None, turntable


def open_board(kind, fw):
    from rangekit.drivers.turntable import FabScanTurntable, HorusTurntable

    return HorusTurntable(fw.port, timeout=2.0, poll_interval=0.002) if kind == "horus" else FabScanTurntable(
        fw.port, timeout=2.0, reset_delay=0.0)


def driven_scan(kind, out, *, s=None, resume=False, n_steps=N_STEPS, **board_options):
    """A laser scan of ``n_steps`` through the ``kind`` driver on a fresh simulated board. Returns (session or
    the DeviceError raised, log of commands and captures, the firmware, the simulated rig)."""
    from rangekit.sim.devices.firmware import start_firmware

    s = s or sim()
    fw = start_firmware(kind, time_scale=0.01)
    log: list[str] = []
    try:
        driver = open_board(kind, fw)
        try:
            board = _DrivenBoard(driver, fw, s.turntable, log, **board_options)
            devices = _Devices(_LoggedCamera(s.camera, log), board)
            try:
                result = acquire(devices, s.rig, LaserSequence(2), out, plan=ScanPlan(n_views=n_steps), resume=resume)
            except DeviceError as exc:
                result = exc
            final_deg = fw.position_deg
        finally:
            driver.close()
    finally:
        fw.stop()
    return result, log, final_deg, fw, s


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """The same scan with the plain simulated devices (the simulator's turntable switches the lasers)."""
    out = tmp_path_factory.mktemp("plain") / "s"
    s = sim()
    acquire(s, s.rig, LaserSequence(2), out, plan=ScanPlan(n_views=N_STEPS))
    return pngs(out)


# The board's commands at each step: the move, the laser-off frame with every laser off, then each laser
# alone: on, the frame, off.
HORUS_STEP = ["G1 X{deg:.4f}", "capture", "M71T1", "capture", "M70T1", "M71T2", "capture", "M70T2"]
FABSCAN_STEP = ["G01 T{steps} F1800", "capture", "M19", "capture", "M20", "M21", "capture", "M22"]


def expected_log(kind, n_steps, first=0):
    out = []
    for k in range(first, n_steps):
        for item in HORUS_STEP if kind == "horus" else FABSCAN_STEP:
            if item.startswith("G01") and k == 0:
                continue                            # FabScan: no move to where the table already is
            out.append(item.format(deg=360.0 * k / n_steps, steps=3200 // n_steps))
    return out


@pytest.mark.parametrize("kind", ["horus", "fabscan"])
def test_laser_scan_through_the_driver_on_the_simulated_board(kind, plain, tmp_path):
    session, log, final_deg, fw, s = driven_scan(kind, tmp_path / "s")
    assert not isinstance(session, Exception), session
    assert all(v.done for v in session.views)
    # First every laser off (a board may start with one on), then per step exactly the expected sequence.
    off_first = ["M70T1", "M70T2"] if kind == "horus" else ["M20", "M22"]
    assert log[:2] == off_first
    assert log[2:] == expected_log(kind, N_STEPS)
    # The last step, to within a microstep; every laser off at the end, on the board and in the simulator.
    assert abs(final_deg - 360.0 * (N_STEPS - 1) / N_STEPS) <= MICROSTEP_DEG
    assert fw.lasers == {1: False, 2: False} and not s.turntable.lasers_on
    # The frames the camera took of what the board lit are those of the plain simulated scan.
    got = pngs(tmp_path / "s")
    assert len(got) == 3 * N_STEPS and got == plain


def test_a_wrong_laser_order_gives_wrong_frames(plain, tmp_path):
    """The mirror is not a formality: a board whose laser 2 is wired as laser 1 gives other frames."""
    class Swapped(_DrivenBoard):
        def laser(self, n, on):
            super().laser(3 - n, on)

    from rangekit.sim.devices.firmware import start_firmware

    s = sim()
    fw = start_firmware("horus", time_scale=0.01)
    try:
        driver = open_board("horus", fw)
        board = Swapped(driver, fw, s.turntable, [])
        acquire(_Devices(s.camera, board), s.rig, LaserSequence(2), tmp_path / "s", plan=ScanPlan(n_views=2))
        driver.close()
    finally:
        fw.stop()
    got = pngs(tmp_path / "s")
    assert got["view_000/off.png"] == plain["view_000/off.png"]
    assert got["view_000/laser0.png"] == plain["view_000/laser1.png"] != plain["view_000/laser0.png"]


@pytest.mark.parametrize("where", [("move", 3), ("laser", 11), ("laser", 13)])
def test_unplug_mid_scan_then_resume_on_a_new_board_gives_identical_bytes(where, plain, tmp_path):
    """The board unplugged before the 4th move (lasers off), before the 12th laser command (step 2's
    M70T1, just after laser 0's frame: switch 1 still on) or before the 14th (step 2's last M70T2): a
    DeviceError naming the view and the step, completed views intact, no partial view. A board unplugged
    with a laser on cannot be told to switch it off; the resumed scan switches every laser off first, and
    ends with every laser off in the simulator."""
    out = tmp_path / "s"
    exc, log, _, fw, s = driven_scan("horus", out, unplug_before=where)
    assert isinstance(exc, DeviceError), exc
    message = str(exc)
    if where[0] == "move":
        assert message.startswith("view 3 (turntable 135.0 deg), turntable move: ")
        assert fw.lasers == {1: False, 2: False} and not s.turntable.lasers_on
    elif where[1] == 11:
        # 2 lasers off at the start, then 4 commands per step: the 12th is step 2's 'M70T1'.
        assert message.startswith("view 2 (turntable 90.0 deg), frame 2 (laser1): lasers: ")
        assert fw.lasers == {1: True, 2: False} and s.turntable.lasers_on == {1}   # the board lost: laser on
    else:
        assert message.startswith("view 2 (turntable 90.0 deg), after frame 2 (laser1): lasers off: ")
        assert fw.lasers == {1: False, 2: True} and s.turntable.lasers_on == {2}
    assert "turntable" in message and "rangekit scan --resume" in message
    n_done = where[1] if where[0] == "move" else 2
    session = load_session(out)
    assert [v.done for v in session.views] == [k < n_done for k in range(N_STEPS)]
    assert not list(out.glob("*.partial"))
    got = pngs(out)
    assert len(got) == 3 * n_done and all(plain[k] == v for k, v in got.items())
    # Resume: a new board and a new driver, the same simulated rig (a laser may still be on in it).
    session, log, final_deg, fw, s = driven_scan("horus", out, s=s, resume=True)
    assert not isinstance(session, Exception), session
    assert all(v.done for v in session.views)
    assert log == ["M70T1", "M70T2"] + expected_log("horus", N_STEPS, first=n_done)
    assert fw.lasers == {1: False, 2: False} and not s.turntable.lasers_on
    assert abs(final_deg - 315.0) <= MICROSTEP_DEG
    assert pngs(out) == plain
    assert not list(out.glob("*.partial"))


# ------------------------------------------------------------------------------------------ bad input

# Processing runs on the full 1280x1024 camera: at 320x256 a pixel spans about 1 mm on the object, and
# profiles are split where consecutive rows' points jump by more than 1 mm (laser/profile_filter.py).

def small_session(out, scene, rig=None, n_steps=4):
    s = SimRig(scene, rig or laser_rig(), seed=0, light="laser")
    acquire(s, s.rig, LaserSequence(2), out, plan=ScanPlan(n_views=n_steps))
    return out


def test_a_dead_laser_is_named(tmp_path, capsys):
    """Laser 2 of the board never lights (the firmware acknowledges M71T2, no light reaches the scene):
    processing stops with a DecodeError naming that laser, its switch and its frames, exit 1."""
    from rangekit.cli.run import main

    session, log, _, fw, _ = driven_scan("horus", tmp_path / "s", s=sim(rig=laser_rig()), n_steps=4, dead={2})
    assert not isinstance(session, Exception), session
    assert log.count("M71T2") == 4                          # it was switched on at every step
    assert main(["process", str(tmp_path / "s"), "--no-report"]) == 1
    err = capsys.readouterr().err
    assert "laser 1 (laser1): no line in any of the 4 steps" in err
    assert "view_000/laser1.png" in err and "its switch 2" in err and "internal error" not in err
    assert not (tmp_path / "s" / "mesh.ply").exists()


@pytest.mark.parametrize("case", ["table only", "object out of view"])
def test_a_missing_object_says_the_lines_are_only_on_the_table(case, tmp_path, capsys):
    """No object on the table, or a small one far out of view: each laser's line is found, only on the
    turntable top; those points are dropped as table points and the error says so (exit 1)."""
    from rangekit.cli.run import main
    from rangekit.geometry import make_T
    from rangekit.sim.scene.objects import sphere
    from rangekit.sim.scene.scene import Scene, turntable_disc

    if case == "table only":
        scene = Scene((turntable_disc(),))
    else:
        ball = sphere(0.002).placed_on_table()
        scene = Scene((ball.with_pose(make_T(t=[0.0, 0.0, 0.6]) @ ball.T_world_obj), turntable_disc()))
    out = small_session(tmp_path / "s", scene)
    assert main(["process", str(out), "--no-report"]) == 1
    err = capsys.readouterr().err
    assert "laser 0 (laser0): its line was found in the 4 steps" in err
    assert "only on the turntable top" in err and "dropped as table points" in err and "no object" in err
    assert "internal error" not in err and not (out / "mesh.ply").exists()


def test_a_saturated_line_is_reported_then_refused(tmp_path, capsys):
    """Laser power 1.5 (2.5x the default): some rows saturate; the scan is processed and the summary and the
    laser info report the saturated rows. Power 50: the line is saturated nearly everywhere: an error
    that says so and what to lower (exit 1), not a cloud of a few points."""
    import json

    from rangekit.cli.run import main

    out = small_session(tmp_path / "bright", default_scene("lumpy"), laser_rig(power=1.5))
    assert main(["process", str(out), "--no-report"]) == 0
    printed = capsys.readouterr().out
    info = json.loads((out / "summary.json").read_text())["laser"]["lasers"]
    saturated = [d["rejected_rows"]["saturated"] for d in info]
    print(f"\npower 1.5: saturated rows {saturated}, points {[d['points'] for d in info]}")
    assert all(n > 50 for n in saturated) and all(d["points"] > 5 * n for d, n in zip(info, saturated))
    assert f"laser0: {info[0]['points']:,} points, no line in 0 step(s), {saturated[0]:,} saturated rows" in printed
    out = small_session(tmp_path / "blinding", default_scene("lumpy"), laser_rig(power=50.0))
    assert main(["process", str(out), "--no-report"]) == 1
    err = capsys.readouterr().err
    assert "laser 0 (laser0): the line is saturated in" in err
    assert "lower the laser power or the camera's exposure" in err and not (out / "mesh.ply").exists()


def test_a_laser_plane_through_the_camera_centre_is_refused_before_any_frame(tmp_path, capsys):
    """A rig file whose second laser's plane passes 0.2 mm from the camera centre: refused naming the rig
    file and the laser before the devices are opened (its board's port does not exist) or a folder made."""
    import json

    from rangekit.cli.run import main
    from rangekit.rig.rig_file import template_rig

    rig = template_rig()               # world = the camera frame: the camera centre is the origin
    rig["lasers"] = [{"name": "left", "plane": [1.0, 0.0, 0.0, -0.1], "switch": 1},
                     {"name": "right", "plane": [1.0, 0.0, 0.0, 0.0002], "switch": 2}]
    rig["devices"]["turntable"]["port"] = str(tmp_path / "no-such-port")
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(rig))
    assert main(["scan", "--method", "laser", "--rig", str(path), "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert f"{path}: lasers[1] ('right'): the plane" in err and "0.200 mm of camera 'camera'" in err
    assert "no-such-port" not in err and not (tmp_path / "s").exists()
    # The same check in the library, for a rig with a good plane nothing is raised.
    from rangekit.app.scan.setup import check_laser_planes
    from rangekit.errors import ConfigError

    check_laser_planes(small_rig(), where="sim")
    bad = replace(small_rig(), lasers=(replace(small_rig().lasers[0], plane=np.append(
        small_rig().lasers[0].normal, -small_rig().lasers[0].normal @ small_rig().camera.center)),))
    with pytest.raises(ConfigError, match=r"my_rig.json: lasers\[0\] \('laser0'\): the plane .* passes within 0.000 mm"):
        check_laser_planes(bad, where="my_rig.json")


@pytest.mark.parametrize("options, message", [
    (["--steps", "1"], "--steps: expected an integer in 2..3600, found '1'"),
    (["--steps", "0"], "--steps: expected an integer in 2..3600, found '0'"),
    (["--patterns", "graycode"], "--patterns: a laser scan projects no patterns"),
    (["--views", "4", "--steps", "8"], "--steps and --views both give the turntable positions"),
])
def test_laser_scan_usage_errors_exit_2(options, message, tmp_path, capsys):
    from rangekit.cli.run import main

    try:
        code = main(["scan", "--method", "laser", "--out", str(tmp_path / "s"), *options])
    except SystemExit as exc:          # argparse refuses an option's value itself
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "s").exists()
