"""The serial turntable drivers against the simulated Horus and FabScan firmware, over a pty (bytes only).

Every fault the firmware can inject is checked for: the right error class, a message naming the port,
the command and the bytes received, a bounded wait, and a next command that works.
"""

import math
import socket
import threading
import time

import pytest

from rangekit.rig.devices import Turntable
from rangekit.drivers.serial_link import SerialLink
from rangekit.drivers.turntable import FabScanTurntable, HorusTurntable, make_turntable
from rangekit.errors import (CommandError, ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout,
                             InputError, ProtocolError)
from rangekit.sim.devices.firmware import start_firmware

TIMEOUT = 0.3  # driver reply timeout in these tests (s)
SLACK = 0.5  # allowed overshoot of a deadline (s)
MICROSTEP_DEG = 360.0 / 3200
SPEED = math.radians(360.0)  # rad/s: driver-side estimates stay short, sim moves take ~ms


def _open(kind, fw, **kw):
    if kind == "horus":
        return HorusTurntable(fw.port, timeout=TIMEOUT, poll_interval=0.005, speed=SPEED, **kw)
    return FabScanTurntable(fw.port, timeout=TIMEOUT, reset_delay=0.05, speed=SPEED, **kw)


@pytest.fixture(params=["horus", "fabscan"])
def board(request):
    """(kind, simulated firmware, connected driver)."""
    kind = request.param
    fw = start_firmware(kind, time_scale=0.01, boot_time=0.02 if kind == "fabscan" else 0.0)
    tt = _open(kind, fw)
    yield kind, fw, tt
    tt.close()
    fw.stop()


def _assert_at(fw, angle, origin_deg=0.0):
    """The firmware's own position is ``angle`` (rad) from ``origin_deg``, within half a microstep."""
    assert not fw.moving
    assert abs(fw.position_deg - origin_deg - math.degrees(angle)) <= MICROSTEP_DEG / 2 + 1e-9


def _assert_recovers(kind, fw, tt):
    """After a fault the next commands work (FabScan: the position is unknown until zero())."""
    if kind == "fabscan":
        with pytest.raises(DeviceError, match="position unknown"):
            tt.rotate_to(0.2)
        tt.zero()
    origin = 0.0 if kind == "horus" else fw.position_deg
    tt.rotate_to(0.2)
    _assert_at(fw, 0.2, origin)
    tt.laser(1, True)
    assert fw.lasers[1] is True


# -- normal operation ---------------------------------------------------------------------------


def test_absolute_moves_land_within_one_microstep(board):
    kind, fw, tt = board
    assert isinstance(tt, Turntable)
    for angle in (0.5, -1.2, 2 * math.pi + 0.3, 1e-4, 0.0, math.radians(30)):
        tt.rotate_to(angle)
        _assert_at(fw, angle)
        assert abs(tt.angle - angle) <= math.radians(MICROSTEP_DEG)


def test_horus_rotate_waits_for_idle_not_for_ok():
    # 90 deg at 22.5 deg/s is 4 s of firmware time, 0.4 s at time_scale 0.1; 'ok' comes at once
    with start_firmware("horus", time_scale=0.1) as fw:
        with HorusTurntable(fw.port, timeout=TIMEOUT, poll_interval=0.01, speed=math.radians(22.5)) as tt:
            polls = fw.status_queries
            t0 = time.monotonic()
            tt.rotate_to(math.pi / 2)
            elapsed = time.monotonic() - t0
            assert elapsed >= 0.35, f"returned after {elapsed:.3f} s, before the motion (0.4 s) ended"
            assert elapsed < 0.4 + SLACK
            assert not fw.moving
            _assert_at(fw, math.pi / 2)
            assert fw.status_queries - polls >= 10  # it polled '?' while the board reported Run
            assert fw.lines[-1] == "G1 X90.0000"


def test_fabscan_rotate_blocks_until_the_prompt():
    with start_firmware("fabscan", time_scale=0.1) as fw:
        with FabScanTurntable(fw.port, timeout=TIMEOUT, reset_delay=0.05, speed=math.radians(22.5)) as tt:
            t0 = time.monotonic()
            tt.rotate_to(math.pi / 2)
            elapsed = time.monotonic() - t0
            assert 0.35 <= elapsed < 0.4 + SLACK
            _assert_at(fw, math.pi / 2)
            assert fw.lines[-1] == "G01 T800 F1350"  # relative microsteps, feed in deg/min
            tt.rotate_to(math.pi / 4)
            assert fw.lines[-1] == "G01 T-400 F1350"
            _assert_at(fw, math.pi / 4)


def test_extras_reach_the_firmware(board):
    kind, fw, tt = board
    tt.enable(True)
    assert fw.motors_on
    tt.enable(False)
    assert not fw.motors_on
    tt.laser(2, True)
    assert fw.lasers[2] is True
    tt.laser(2, False)
    assert fw.lasers[2] is False
    tt.rotate_to(1.0)
    tt.zero()
    assert abs(tt.angle) < 1e-12
    tt.rotate_to(0.1)
    _assert_at(fw, 0.1, origin_deg=math.degrees(1.0) if kind == "fabscan" else 0.0)
    with pytest.raises(InputError):
        tt.rotate_to(float("nan"))
    with pytest.raises(InputError):
        tt.set_speed(0.0)
    with pytest.raises(InputError):
        tt.laser(0, True)


def test_horus_speed_and_acceleration_units():
    with start_firmware("horus") as fw, HorusTurntable(fw.port, timeout=TIMEOUT) as tt:
        tt.set_speed(math.radians(10))
        assert fw.lines[-1] == "G1 F600.000" and fw.feed == pytest.approx(600.0)
        tt.set_acceleration(math.radians(200))
        assert fw.acceleration == pytest.approx(200.0)


# -- faults -------------------------------------------------------------------------------------


def test_silent_board_times_out_within_the_deadline(board):
    kind, fw, tt = board
    fw.inject("silence")
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout) as err:
        tt.enable(True)
    elapsed = time.monotonic() - t0
    assert elapsed <= TIMEOUT + SLACK
    msg = str(err.value)
    assert fw.port in msg and "'M17'" in msg and "received b''" in msg
    tt.enable(True)
    assert fw.motors_on
    tt.rotate_to(0.4)  # a silenced non-move leaves the position known
    _assert_at(fw, 0.4)


def test_partial_reply_is_in_the_timeout_message(board):
    kind, fw, tt = board
    fw.inject("partial")
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout) as err:
        tt.rotate_to(math.radians(45))  # 400 microsteps exactly
    assert time.monotonic() - t0 <= 2 * TIMEOUT + SLACK  # + a status query (Horus) or the move margin
    msg = str(err.value)
    expected = ("no 'ok' within 0.3 s after 'G1 X45.0000'; received b'o'" if kind == "horus"
                else "after 'G01 T400 F21600'; received b'G'")
    assert fw.port in msg and expected in msg, msg
    _assert_recovers(kind, fw, tt)


def test_garbage_reply_is_a_protocol_error(board):
    kind, fw, tt = board
    fw.inject("garbage")
    with pytest.raises(ProtocolError, match="non-ASCII") as err:
        tt.rotate_to(1.0)
    assert fw.port in str(err.value) and "baud" in str(err.value)
    _assert_recovers(kind, fw, tt)


def test_reboot_mid_command_is_detected(board):
    kind, fw, tt = board
    tt.rotate_to(math.radians(45))
    fw.inject("reboot")
    t0 = time.monotonic()
    # Horus prints its banner instead of 'ok'; a FabScan goes silent after echoing one byte
    expected = (ProtocolError, "reset during 'G1 X90.0000'") if kind == "horus" else (DeviceTimeout, "b'G'")
    with pytest.raises(expected[0]) as err:
        tt.rotate_to(math.radians(90))
    assert expected[1] in str(err.value) and fw.port in str(err.value)
    assert time.monotonic() - t0 <= 2 * TIMEOUT + SLACK
    assert fw.position_deg == 0.0  # the board lost its position
    _assert_recovers(kind, fw, tt)


def test_horus_error_reply_is_a_command_error():
    with start_firmware("horus") as fw, HorusTurntable(fw.port, timeout=TIMEOUT) as tt:
        fw.inject("error")
        with pytest.raises(CommandError, match=r"'M71T1' was refused: expected 'ok', received 'error:"):
            tt.laser(1, True)
        tt.laser(1, True)
        assert fw.lasers[1] is True


def test_unplugged_board_is_disconnected(board):
    kind, fw, tt = board
    fw.inject("unplug")
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="unplugged") as err:
        tt.rotate_to(1.0)
    assert time.monotonic() - t0 < TIMEOUT + SLACK
    assert fw.port in str(err.value)
    with pytest.raises(DeviceDisconnected):
        tt.enable(True)


# -- opening ------------------------------------------------------------------------------------


def test_wrong_baud_rate_is_a_protocol_error_naming_the_port():
    # at a wrong baud rate the banner arrives as non-ASCII bytes: the firmware sends garbage instead
    with start_firmware("horus", faults=["garbage"]) as fw:
        with pytest.raises(ProtocolError, match="Horus banner.*baud rate") as err:
            HorusTurntable(fw.port, timeout=TIMEOUT)
        assert fw.port in str(err.value)
        HorusTurntable(fw.port, timeout=TIMEOUT).close()  # the board itself is fine


def test_horus_driver_on_a_fabscan_board():
    with start_firmware("fabscan") as fw:
        with pytest.raises(ProtocolError, match=r"Horus banner .* received non-ASCII bytes b'\\x18'") as err:
            HorusTurntable(fw.port, timeout=TIMEOUT)
        assert fw.port in str(err.value)


def test_fabscan_driver_on_a_horus_board():
    with start_firmware("horus") as fw:
        with pytest.raises(ProtocolError, match=r"expected the echo 'M200'.*received b'error: ") as err:
            FabScanTurntable(fw.port, timeout=TIMEOUT, reset_delay=0.0)
        assert fw.port in str(err.value) and "protocol 'fabscan'" in str(err.value)


def test_fabscan_reset_delay_covers_the_boot():
    with start_firmware("fabscan", boot_time=0.3) as fw:
        with pytest.raises(DeviceTimeout, match="M200"):  # the boot swallowed the version query
            FabScanTurntable(fw.port, timeout=0.1, reset_delay=0.0)
    with start_firmware("fabscan", boot_time=0.3) as fw:
        with FabScanTurntable(fw.port, timeout=0.1, reset_delay=0.35) as tt:
            assert tt.version.startswith("FabScan")


def test_missing_port_fails_fast_and_says_how_to_list_ports():
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="rangekit devices") as err:
        HorusTurntable("/dev/rangekit-no-such-port", timeout=TIMEOUT)
    assert time.monotonic() - t0 < 1.0
    assert "/dev/rangekit-no-such-port" in str(err.value)


def test_factory_builds_drivers_and_rejects_unknown_protocols():
    with start_firmware("horus") as fw:
        with make_turntable("Horus", fw.port, timeout=TIMEOUT) as tt:
            assert isinstance(tt, HorusTurntable) and isinstance(tt, Turntable)
    with start_firmware("fabscan") as fw:
        with make_turntable("fabscan", fw.port, 57600, timeout=TIMEOUT, reset_delay=0.0) as tt:
            assert isinstance(tt, FabScanTurntable)
    with pytest.raises(ConfigError, match="'grbl' is not known; known protocols: 'fabscan', 'horus'"):
        make_turntable("grbl", "/dev/null")


# -- the link over socket:// ------------------------------------------------------------------------


def test_serial_link_over_a_socket():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def serve():
        conn, _ = server.accept()
        with conn:
            conn.sendall(b"")
            data = b""
            while b"\n" not in data:
                data += conn.recv(64)
            conn.sendall(b"[MSG:hello]\r\nok\r\n")
            conn.recv(64)  # the second command is never answered
            time.sleep(TIMEOUT + 0.2)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    url = f"socket://127.0.0.1:{server.getsockname()[1]}"
    with SerialLink(url, 115200, timeout=TIMEOUT, name="turntable") as link:
        assert link.command("G50") == ["[MSG:hello]"]
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeout, match=f"turntable at {url}: no 'ok' within 0.3 s after 'M17'"):
            link.command("M17")
        assert time.monotonic() - t0 <= TIMEOUT + SLACK
    thread.join(timeout=2)
    server.close()
