"""Device faults: ``rangekit devices`` never aborts whatever the search timeout,
and an error message quotes at most 200 bytes of what a device sent, escaped.

The depthai cases run real child processes: the abort they guard against (``terminate called without an
active exception``, SIGABRT, exit 134) happened when the interpreter exited while an abandoned search
thread was still inside depthai. The serial cases talk to a board faked on a real pty (or a loopback TCP
peer for PJLink) that answers the driver's first bytes with a bad reply.
"""

from __future__ import annotations

import json
import os
import select
import socket
import subprocess
import sys
import threading
import tty
from contextlib import contextmanager

import pytest

from support.cli_runs import ROOT, Run, assert_error, cli_process

from rangekit.errors import QUOTE_LIMIT, ConfigError, DeviceError, DeviceTimeout, ProtocolError

ABORT_SIGNS = ("terminate called", "Stack trace", "Aborted", "Traceback", "internal error")
LONG = 10_000


def _clean_exit(run, code: int = 0) -> None:
    assert run.code == code, f"exit {run.code}\nstdout: {run.out[-2000:]}\nstderr: {run.err[-3000:]}"
    for sign in ABORT_SIGNS:
        assert sign not in run.err + run.out, run.err[-3000:]


# ----------------------------------------------------------------------------- depthai search
@pytest.mark.parametrize("timeout", ["0", "0.05", "0.2", "0.5"])
def test_devices_with_a_short_timeout_returns_cleanly(timeout):
    """Every timeout below depthai's old fixed 0.5 s search ended in SIGABRT (exit 134) before."""
    run = cli_process("devices", "--timeout", timeout, timeout=120)
    _clean_exit(run)
    assert "serial ports" in run.out
    pytest.importorskip("depthai")
    line = next(ln for ln in run.out.splitlines() if ln.startswith("depthai cameras:"))
    assert line.startswith("depthai cameras: none found") or run.out.count("\n  ") >= 1, run.out
    assert f"search limit {float(timeout):g} s" in line


@pytest.mark.parametrize("value", ["nan", "-0.1", "inf", "1e9", "soon"])
def test_devices_refuses_a_timeout_that_is_not_a_duration(cli, value):
    assert_error(cli("devices", "--timeout", value), 2, "--timeout", f"'{value}'", "0..600")


@pytest.mark.parametrize("timeout", [float("nan"), -1.0, float("inf"), 1e9, "1"])
def test_the_discovery_function_refuses_a_bad_timeout(timeout):
    from rangekit.drivers.discovery import list_depthai_devices

    with pytest.raises(ConfigError, match="depthai search timeout"):
        list_depthai_devices(timeout_s=timeout)


def test_opening_a_depthai_camera_with_short_timeouts_never_aborts():
    """DepthaiCamera gives up with DeviceDisconnected within its timeout (plus one depthai call), names
    the timeout asked, and the process exits normally afterwards."""
    pytest.importorskip("depthai")
    code = (
        "import time\n"
        "import depthai\n"
        "from rangekit.drivers.depthai.camera import DepthaiCamera\n"
        "from rangekit.errors import RangekitError\n"
        "for t in (0.0, 0.05, 0.2, float('nan')):\n"
        "    try:\n"
        "        DepthaiCamera(search_timeout_s=t)\n"
        "        print('OPENED', t)\n"
        "    except RangekitError as exc:\n"
        "        print(type(exc).__name__, '|', exc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    run = Run(proc.returncode, proc.stdout, proc.stderr)
    _clean_exit(run)
    lines = [ln for ln in run.out.splitlines() if "|" in ln or ln.startswith("OPENED")]
    if any(ln.startswith("OPENED") for ln in lines):
        pytest.skip("a depthai device is attached")
    assert [ln.split(" |")[0] for ln in lines] == ["DeviceDisconnected"] * 3 + ["ConfigError"], run.out
    for ln, t in zip(lines, ("0", "0.05", "0.2")):
        assert f"search_timeout_s={t} s" in ln


# ----------------------------------------------------------------------------- a fake board on a pty
@contextmanager
def fake_board(reply: bytes):
    """A pty whose far end answers the first bytes it receives with ``reply``, then stays silent.

    Writes are non-blocking, so a driver that stops reading (it refused the reply) cannot wedge it.
    Yields the port path to give to a driver.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    stop = threading.Event()

    def run() -> None:
        todo = b""
        triggered = False
        while not stop.is_set():
            r, w, _ = select.select([master], [master] if todo else [], [], 0.01)
            try:
                if r and os.read(master, 4096) and not triggered:
                    triggered, todo = True, reply
                if w and todo:
                    todo = todo[os.write(master, todo[:4096]):]
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                return

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield os.ttyname(slave)
    finally:
        stop.set()
        thread.join(timeout=2)
        os.close(master)
        os.close(slave)


def _bounded(message: str, port: str) -> None:
    """Names the port, escapes every control character, and quotes a bounded part of the reply."""
    assert port in message, message
    assert message.isprintable(), repr(message)
    assert len(message) < 4 * QUOTE_LIMIT + 700, f"{len(message)} characters: {message[:300]}..."


BAD_REPLIES = {
    # reply -> (error class, words of the message)
    "10 kB line": (b"A" * LONG + b"\r\n", ProtocolError, ["more than 4096 bytes"]),
    "10 kB without a newline": (b"B" * LONG, ProtocolError, ["more than 4096 bytes"]),
    "3 kB line": (b"C" * 3000 + b"\r\n", ProtocolError, ["expected the banner", "(3001 bytes)"]),
    "binary garbage": (bytes(range(256)) * 40, ProtocolError, ["non-ASCII", "bytes)"]),
    "terminal escapes": (b"\x1b[2J\x1b[31mHorus 0.2\x07\r\n", ProtocolError, ["non-ASCII", "\\x1b"]),
    "no newline at all": (b"Horus 0.2 ['$' for", ProtocolError, ["expected the banner", "Horus 0.2"]),
    "silence": (b"", DeviceTimeout, ["no answer to Ctrl-X"]),
}


@pytest.mark.parametrize("case", list(BAD_REPLIES))
def test_a_bad_turntable_reply_is_quoted_short_and_escaped(case):
    from rangekit.drivers.turntable import HorusTurntable

    reply, error, words = BAD_REPLIES[case]
    with fake_board(reply) as port:
        with pytest.raises(error) as info:
            HorusTurntable(port, timeout=0.5)
    message = str(info.value)
    _bounded(message, port)
    for w in words:
        assert w in message, message


@pytest.fixture
def horus_rig(cli, tmp_path):
    """``rangekit rig init``'s template with its turntable on ``port`` (the first device a scan opens)."""
    def make(port: str):
        data = json.loads(cli("rig", "init").out)
        data["devices"]["turntable"]["port"] = port
        path = tmp_path / "rig.json"
        path.write_text(json.dumps(data))
        return path
    return make


@pytest.mark.parametrize("case", ["10 kB line", "binary garbage", "terminal escapes"])
def test_scan_on_a_babbling_turntable_exits_1_with_a_short_message(cli, tmp_path, horus_rig, case):
    reply, _, words = BAD_REPLIES[case]
    with fake_board(reply) as port:
        run = cli("scan", "--rig", horus_rig(port), "--out", tmp_path / "session")
    line = assert_error(run, 1, port, *words)
    _bounded(line, port)
    assert "\x1b" not in run.err and "\x00" not in run.err
    assert not (tmp_path / "session").exists()


def test_a_fabscan_echo_of_10_kb_is_quoted_short():
    from rangekit.drivers.turntable import FabScanTurntable

    with fake_board(b"M" * LONG + b"\r\n") as port:
        with pytest.raises(ProtocolError) as info:
            FabScanTurntable(port, timeout=0.5, reset_delay=0.0)
    _bounded(str(info.value), port)


@pytest.mark.parametrize("reply, words", [
    (b"PWR=" + b"9" * LONG + b"\r:", ["more than 4096 bytes"]),
    (b"\xff\xfe\x00ERR\r:", ["non-ASCII", "\\xff"]),
])
def test_a_bad_escvp21_reply_is_quoted_short(reply, words):
    from rangekit.drivers.projector_control import EscVp21Projector

    with fake_board(reply) as port:
        with pytest.raises(DeviceError) as info:
            EscVp21Projector(port, timeout=0.5)
    _bounded(str(info.value), port)
    for w in words:
        assert w in str(info.value)


@contextmanager
def fake_pjlink(greeting: bytes, answer: bytes = b""):
    """A loopback TCP peer: sends ``greeting`` on connect and ``answer`` to the first command."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    srv.settimeout(5)

    def run() -> None:
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        with conn:
            try:
                conn.sendall(greeting)
                if answer and conn.recv(1024):
                    conn.sendall(answer)
                conn.recv(1024)  # until the driver closes
            except OSError:
                pass

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield srv.getsockname()[1]
    finally:
        srv.close()
        thread.join(timeout=2)


@pytest.mark.parametrize("greeting, answer, error, words", [
    (b"P" * LONG, b"", ProtocolError, ["more than 4096 bytes without a CR"]),
    (b"PJLINK 0\r", b"%1POWR=" + b"x" * LONG + b"\r", ProtocolError, ["more than 4096 bytes without a CR"]),
    (b"PJLINK 0\r", b"%1POWR=ERR" + b"x" * 3000 + b"\r", DeviceError, ["(3003 characters)"]),
    (b"PJLINK \x1b[5m0\r", b"", ProtocolError, ["\\x1b"]),
])
def test_a_bad_pjlink_reply_is_quoted_short(greeting, answer, error, words):
    from rangekit.drivers.projector_control import PJLinkProjector

    with fake_pjlink(greeting, answer) as port:
        with pytest.raises(error) as info:
            p = PJLinkProjector("127.0.0.1", port, timeout=0.5)
            try:
                p.power(True)
            finally:
                p.close()
    _bounded(str(info.value), f"127.0.0.1:{port}")
    for w in words:
        assert w in str(info.value)
