"""Hardware that goes away mid-scan (issue 34, section 3), on the project's own fake devices.

``rangekit scan --rig RIG.json`` runs its hardware path (:func:`rangekit.drivers.open_rig_devices`) on:

- the turntable: the real Horus driver on the simulated firmware over a pty (:mod:`rangekit.sim.devices.firmware`),
  named in the rig file by a link kept to the board's pty, as udev's ``/dev/serial/by-id/...`` links are;
- the projector: the real pygame display driver on SDL's dummy video driver;
- the camera: the real depthai driver on the fake ``depthai`` module at the API boundary
  (tests/support/fake_depthai.py, as in tests/drivers/test_depthai_controls.py) whose frames are the simulator's
  camera looking at what the pygame window shows, with the table where the simulated board turned it. It raises what real depthai raises when
  a device resets (RuntimeError "Communication exception ... (X_LINK_ERROR)") and finds no device while it is away.

Each case: the device lost and not back in time ends the scan with exit 1 and one error line naming the device
and what to check, every finished view kept; ``rangekit scan --resume DIR`` once it is back completes the
session with the frames of an uninterrupted simulated scan, byte for byte. A device back within the rig file's
``devices.<device>.reconnect_timeout_s`` is reconnected without ending the scan, the view in progress taken
again: the same bytes.
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import replace
from typing import Callable

import numpy as np
import pytest

from support.cli_runs import assert_error
from support.sessions import pngs
from support.small_rigs import small_rig
from support.fake_depthai import FakeDepthai, Frame

from rangekit.app.acquire.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import FRAME_FORMATS, CaptureSettings, ScanPlan, load_session
from rangekit.rig.camera_controls import CameraControls, controls_from_capture
from rangekit.rig.rig_file import save_rig
from rangekit.sim import SimRig, default_scene
from rangekit.sim.devices.firmware import start_firmware

pygame = pytest.importorskip("pygame", reason="optional extra 'display' (pygame) not installed")

N_VIEWS, PATTERNS = 4, "graycode"      # 90 deg steps: whole microsteps of the board, exact in its reports
PROJECTOR = (1024, 768)                 # SDL's dummy display: the full-screen window's size
N_FRAMES = make_pattern_spec(PATTERNS, PROJECTOR).n_frames
MXID = "SIM-OAK-0001"
X_LINK_ERROR = ("Communication exception - possible device error/misconfiguration. Original message "
                "'Couldn't read data from stream: '__x_0_raw' (X_LINK_ERROR)'")


def hardware_rig(port: str, **reconnect_s):
    """The small simulated rig as a hardware rig file: a Horus board on ``port`` (replies within 0.5 s), the
    projector on SDL display 0 (at that display's size, as a real one at its native resolution), an OAK camera;
    no waits; ``reconnect_s``: device -> reconnect_timeout_s."""
    devices = {"turntable": {"protocol": "horus", "port": port, "timeout_s": 0.5},
               "projector": {"display": 0},
               "camera": {"type": "depthai", "id": None, "socket": "CAM_A", "search_timeout_s": 0}}
    for name, seconds in reconnect_s.items():
        devices[name]["reconnect_timeout_s"] = seconds
    rig = small_rig()
    capture = {"bits": 8, "pattern_delay_s": 0, "turntable_settle_s": 0, "camera": CameraControls(mono=True).to_dict()}
    return replace(rig, projector=rig.projector.resized(*PROJECTOR), devices=devices, capture=capture)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The frames of the uninterrupted simulated scan (the simulator's own devices, seed 0)."""
    rig = hardware_rig("/dev/unused")
    out = tmp_path_factory.mktemp("reference") / "s"
    acquire(SimRig(default_scene("lumpy"), rig, seed=0), rig, make_pattern_spec(PATTERNS, PROJECTOR), out,
            plan=ScanPlan(N_VIEWS),   # in the frame format `rangekit scan` writes
            capture=replace(CaptureSettings.from_rig(rig, hardware=False), frame_format=FRAME_FORMATS[0]))
    return pngs(out)


# ----------------------------------------------------------------------------- the fake OAK camera
class Oak:
    """The fake camera's world: the simulator's camera sees what the pygame window shows, on the table where the
    simulated board ``fw`` turned it (each move command the board receives starts the view's noise afresh, so a
    view taken again records the same bytes). ``after[n]()`` runs once frame n (from 0) is taken."""

    def __init__(self, fw, rig):
        self.fw, self.sim = fw, SimRig(default_scene("lumpy"), rig, seed=0)
        self.sim.camera.set_controls(controls_from_capture(rig.capture, where="rig"))
        self.after: dict[int, Callable[[], object]] = {}
        self.frames, self.generation, self.away, self._lines, self.how = 0, 0, 0, 0, "reset"

    def reset(self, away: int | None = 3, how: str = "reset") -> None:
        """The device goes away: ``how`` "reset" (its streams fail with X_LINK_ERROR, a RuntimeError) or "unplugged"
        (depthai v3 closes its queues: MessageQueue.QueueException); ``away`` searches find nothing (None: until
        :meth:`back`)."""
        self.generation, self.away, self.how = self.generation + 1, away, how

    def back(self) -> None:
        self.away = 0

    def answers(self) -> bool:
        """Whether a device search finds it."""
        if self.away is None:
            return False
        if self.away > 0:
            self.away -= 1
            return False
        return True

    def frame(self) -> np.ndarray:
        lines, self._lines = self.fw.lines[self._lines:], len(self.fw.lines)
        if any(line.startswith("G1") and "X" in line for line in lines):
            self.sim.turntable.rotate_to(math.radians(round(self.fw.position_deg, 3)))  # as the board reports it
            self.sim.restart_noise()
        surface = pygame.display.get_surface()
        shown = np.zeros(PROJECTOR[::-1], np.uint8) if surface is None else np.array(pygame.surfarray.pixels_red(
            surface).T)
        self.sim.projector.show(shown)
        image = self.sim.camera.capture()
        n, self.frames = self.frames, self.frames + 1
        self.after.pop(n, lambda: None)()
        return image


class OakDepthai(FakeDepthai):
    """The fake depthai (tests/support/fake_depthai.py) over ``oak``: one camera, CAM_A, found while the Oak
    answers; its frames the Oak's; a queue of a device opened before the Oak went away fails as depthai's do
    (X_LINK_ERROR, a RuntimeError, when it reset; MessageQueue.QueueException when it was unplugged)."""

    mxid = MXID

    def __init__(self, oak: Oak):
        self.oak = oak
        super().__init__(sockets=("CAM_A",))

    def answers(self) -> bool:
        return self.oak.answers()

    def opened(self, device) -> None:
        device.generation = self.oak.generation

    def check(self, queue) -> None:
        if queue.device.generation != self.oak.generation:
            raise (RuntimeError(X_LINK_ERROR) if self.oak.how == "reset" else
                   self.module.MessageQueue.QueueException("MessageQueue was closed"))

    def message(self, queue):
        return Frame(self.oak.frame())


@pytest.fixture
def rig_world(tmp_path, monkeypatch):
    """``make(**reconnect_s)`` -> (rig file, firmware, oak): a simulated Horus board reached through the link
    ``tmp_path/ttyUSB-turntable``, SDL's dummy display, the fake depthai over a fresh :class:`Oak`."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    boards = []

    def make(**reconnect_s):
        fw = start_firmware("horus", time_scale=0.001, link=tmp_path / "ttyUSB-turntable")
        boards.append(fw)
        rig = hardware_rig(fw.link, **reconnect_s)
        path = tmp_path / "rig.json"
        save_rig(rig, path)
        oak = Oak(fw, rig)
        OakDepthai(oak).install(monkeypatch)
        return path, fw, oak

    yield make
    for fw in boards:
        fw.stop()
    pygame.display.quit()


def scan(cli, rig_file, out):
    return cli("scan", "--rig", rig_file, "--out", out, "--views", N_VIEWS, "--patterns", PATTERNS, "--no-process")


def ends_then_resumes(cli, out, run, reference, n_done, back, *mentions) -> str:
    """The scan ended with exit 1 and one error line naming ``mentions``, kept its ``n_done`` finished views (byte
    for byte those of the uninterrupted scan) and nothing half-written; once ``back()`` brought the device
    back, ``--resume`` completes it with the uninterrupted scan's frames. Returns the error line."""
    line = assert_error(run, 1, *mentions, "--resume")
    assert sum(ln.startswith("rangekit: error:") for ln in run.err.splitlines()) == 1, run.err
    assert len(load_session(out).done_views) == n_done
    kept = pngs(out)
    assert len(kept) == n_done * N_FRAMES and all(reference[k] == v for k, v in kept.items())
    assert not list(out.glob("*.partial"))
    back()
    resumed = cli("scan", "--resume", out, "--no-process")
    assert resumed.code == 0, resumed.err
    assert pngs(out) == reference
    return line


# ----------------------------------------------------------------------------- the camera
@pytest.mark.parametrize("how, said", [("reset", "X_LINK_ERROR"), ("unplugged", "MessageQueue was closed")])
def test_camera_reset_or_unplugged_ends_the_scan_then_resume_gives_identical_bytes(cli, rig_world, reference,
                                                                                  tmp_path, how, said):
    """The OAK resets (X_LINK_ERROR) or is unplugged (its queues closed) mid-view, and does not answer again
    within 0.3 s."""
    rig_file, fw, oak = rig_world(camera=0.3)
    oak.after = {N_FRAMES + 20: lambda: oak.reset(away=None, how=how)}
    out = tmp_path / "s"
    line = ends_then_resumes(cli, out, scan(cli, rig_file, out), reference, 1, oak.back,
                             f"depthai {MXID} CAM_A", said, "check its USB/PoE cable and power",
                             "not back within devices.camera.reconnect_timeout_s=0.3 s", "view 1", "frame 21")
    print(f"\n{line}")


def test_camera_reset_and_back_within_the_timeout_is_reconnected(cli, rig_world, reference, tmp_path):
    """The OAK resets mid-view and answers again a few searches later: the scan goes on, the view taken again."""
    rig_file, fw, oak = rig_world(camera=10)
    oak.after = {N_FRAMES + 20: lambda: oak.reset(away=3)}
    run = scan(cli, rig_file, tmp_path / "s")
    assert run.code == 0, run.err
    assert "the camera is back; the view is taken again" in run.err
    assert pngs(tmp_path / "s") == reference


@pytest.mark.slow
def test_camera_that_keeps_resetting_ends_the_scan_after_three_retakes(cli, rig_world, reference, tmp_path):
    """A view is taken again at most 3 times (MAX_RETAKES): a camera that resets in each attempt ends the scan,
    with the loss itself; the finished view stays."""
    from rangekit.app.acquire.reconnect import MAX_RETAKES

    rig_file, fw, oak = rig_world(camera=10)
    oak.after = {N_FRAMES + 5 * (k + 1): lambda: oak.reset(away=0) for k in range(MAX_RETAKES + 1)}
    run = scan(cli, rig_file, tmp_path / "s")
    line = assert_error(run, 1, f"depthai {MXID} CAM_A", "X_LINK_ERROR", "view 1", "--resume")
    assert "not back" not in line and run.err.count("the camera is back") == MAX_RETAKES
    assert len(load_session(tmp_path / "s").done_views) == 1


# ----------------------------------------------------------------------------- the serial port
@pytest.mark.slow
def test_turntable_port_gone_ends_the_scan_then_resume_gives_identical_bytes(cli, rig_world, reference, tmp_path):
    """The board's USB link goes away (the pty closes: EIO; its path and link vanish) while view 1 is taken;
    the next move fails, and the port is not back within 0.3 s."""
    rig_file, fw, oak = rig_world(turntable=0.3)
    oak.after = {N_FRAMES + 5: lambda: fw.inject("unplug")}
    out = tmp_path / "s"
    line = ends_then_resumes(cli, out, scan(cli, rig_file, out), reference, 2, fw.replug,
                             f"turntable at {fw.link}", "turntable move", "check its USB cable and power",
                             "not back within devices.turntable.reconnect_timeout_s=0.3 s", "view 2")
    print(f"\n{line}")


def test_turntable_port_back_within_the_timeout_is_reconnected(cli, rig_world, reference, tmp_path):
    """The board is plugged in again 0.2 s after it went away (a new pty behind the same link)."""
    rig_file, fw, oak = rig_world(turntable=10)
    oak.after = {N_FRAMES + 5: lambda: (fw.inject("unplug"), threading.Timer(0.2, fw.replug).start())}
    run = scan(cli, rig_file, tmp_path / "s")
    assert run.code == 0, run.err
    assert "the turntable is back; the view is taken again" in run.err
    assert pngs(tmp_path / "s") == reference


@pytest.mark.slow
def test_turntable_back_without_its_origin_ends_the_scan(cli, rig_world, reference, tmp_path):
    """A board powered from USB restarts when plugged in again: at X=0 wherever the table stands. The scan must
    not go on at wrong angles: exit 1 saying so. The simulated table stands where its board says, so it is at
    its start already (a user turns it back): the resume gives identical bytes."""
    rig_file, fw, oak = rig_world(turntable=10)
    oak.after = {N_FRAMES + 5: lambda: (fw.inject("unplug"), fw.replug(restarted=True))}
    out = tmp_path / "s"
    line = ends_then_resumes(cli, out, scan(cli, rig_file, out), reference, 2, lambda: None,
                             f"turntable at {fw.link}", "lost its origin", "X=0.000 deg", "was at 90.000 deg")
    print(f"\n{line}")


@pytest.mark.slow
def test_fabscan_board_replugged_is_reconnected_but_a_move_cut_short_is_refused(tmp_path):
    """The FabScan driver greets the board again on its link; it keeps its step counter, which a move cut short by
    the unplug leaves unknown: the next move says so instead of turning to a wrong angle."""
    from rangekit.drivers.turntable import FabScanTurntable
    from rangekit.errors import DeviceDisconnected, DeviceError

    with start_firmware("fabscan", time_scale=0.001, link=tmp_path / "ttyACM-fabscan") as fw:
        table = FabScanTurntable(fw.link, timeout=0.5, reset_delay=0.0)
        table.rotate_to(math.pi / 2)
        fw.inject("unplug")
        with pytest.raises(DeviceDisconnected, match=f"turntable at {fw.link}: .*check its USB cable and power"):
            table.rotate_to(math.pi)
        with pytest.raises(DeviceDisconnected, match="cannot open the port"):
            table.reconnect(0.2)                    # not back: the link is gone
        threading.Timer(0.1, fw.replug).start()
        table.reconnect(5.0)
        assert table.version.startswith("FabScan")
        with pytest.raises(DeviceError, match="position unknown"):
            table.rotate_to(0.0)
        table.zero()
        table.rotate_to(math.pi / 2)
        assert abs(fw.position_deg - 180.0) < 0.2
        table.close()


# ----------------------------------------------------------------------------- a turntable that stalls
@pytest.mark.slow
def test_turntable_stall_times_out_and_ends_the_scan_then_resume_gives_identical_bytes(cli, rig_world, reference,
                                                                                      tmp_path):
    """The firmware stops answering (it reads and drops everything): the driver times out (0.5 s per reply),
    never hangs, and the board does not answer again within 0.3 s."""
    rig_file, fw, oak = rig_world(turntable=0.3)
    oak.after = {N_FRAMES + 5: lambda: fw.inject("stall")}
    out = tmp_path / "s"
    line = ends_then_resumes(cli, out, scan(cli, rig_file, out), reference, 2, fw.recover,
                             f"turntable at {fw.link}", "within 0.5 s", "check that the board is powered",
                             "not back within devices.turntable.reconnect_timeout_s=0.3 s", "view 2")
    print(f"\n{line}")


def test_turntable_stall_that_ends_within_the_timeout_is_reconnected(cli, rig_world, reference, tmp_path):
    """The stalled board answers again once the driver has started greeting it anew (its Ctrl-X was dropped)."""
    rig_file, fw, oak = rig_world(turntable=10)

    def stall():
        fw.inject("stall")
        threading.Thread(target=_when, args=(lambda: b"\x18" in fw.ignored, fw.recover), daemon=True).start()

    oak.after = {N_FRAMES + 5: stall}
    run = scan(cli, rig_file, tmp_path / "s")
    assert run.code == 0, run.err
    assert "the turntable is back; the view is taken again" in run.err
    assert pngs(tmp_path / "s") == reference


def _when(condition, action, limit_s: float = 30.0) -> None:
    """Run ``action()`` once ``condition()`` holds (polled; given up after ``limit_s`` seconds)."""
    deadline = time.monotonic() + limit_s
    while not condition():
        if time.monotonic() > deadline:
            return
        time.sleep(0.005)
    action()


# ----------------------------------------------------------------------------- the projector's display
@pytest.mark.slow
def test_projector_display_gone_ends_the_scan_then_resume_gives_identical_bytes(cli, rig_world, reference,
                                                                               tmp_path, monkeypatch):
    """The display goes away mid-view (SDL's video is shut down) and cannot be brought up within 0.3 s (SDL has
    no video driver meanwhile)."""
    rig_file, fw, oak = rig_world(projector=0.3)

    def gone():
        pygame.display.quit()
        monkeypatch.setenv("SDL_VIDEODRIVER", "rangekit-display-unplugged")

    oak.after = {2 * N_FRAMES + 10: gone}
    out = tmp_path / "s"
    line = ends_then_resumes(cli, out, scan(cli, rig_file, out), reference, 2,
                             lambda: monkeypatch.setenv("SDL_VIDEODRIVER", "dummy"),
                             "projector display 0", "check the projector's power, its video cable",
                             "not back within devices.projector.reconnect_timeout_s=0.3 s", "view 2", "frame 11")
    print(f"\n{line}")


def test_projector_display_back_within_the_timeout_is_reconnected(cli, rig_world, reference, tmp_path):
    rig_file, fw, oak = rig_world(projector=10)
    oak.after = {2 * N_FRAMES + 10: pygame.display.quit}
    run = scan(cli, rig_file, tmp_path / "s")
    assert run.code == 0, run.err
    assert "the projector is back; the view is taken again" in run.err
    assert pngs(tmp_path / "s") == reference


# ----------------------------------------------------------------------------- the rig file's fields
@pytest.mark.parametrize("field, value", [("turntable.reconnect_timeout_s", -1), ("camera.reconnect_timeout_s", "10"),
                                          ("projector.reconnect_timeout_s", float("nan")),
                                          ("turntable.timeout_s", 0)])
def test_bad_reconnect_and_reply_timeouts_are_refused_naming_the_field(cli, tmp_path, field, value):
    data = hardware_rig("/dev/ttyUSB0").to_dict()
    device, key = field.split(".")
    data["devices"][device][key] = value
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(data))
    assert_error(cli("scan", "--rig", path, "--out", tmp_path / "s", "--no-process"), 1, f"devices.{field}",
                 "must be a number of seconds")
    assert not (tmp_path / "s").exists()
