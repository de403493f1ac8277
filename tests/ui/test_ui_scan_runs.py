"""A scan started from the app is an ordinary session (issue 37): stopped and resumed from the page, and left
resumable when the server is killed mid-scan, completed byte-identical by ``rangekit scan --resume``."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from support.ui_server import start_ui

pytestmark = pytest.mark.slow


def _scan(server) -> dict:
    return json.loads(server.request("/api/scan")[1])


def _until(server, test, timeout: float = 300.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        s = _scan(server)
        if test(s):
            return s
        time.sleep(0.3)
    raise AssertionError(f"never reached: {_scan(server)}")


def _done(s: dict) -> int:
    return sum(v["done"] for v in s["views"])


def test_stop_keeps_the_views_taken_and_resume_completes(tmp_path):
    server = start_ui(tmp_path)
    try:
        assert server.request("/api/scan/start", data={"name": "a", "views": 4})[0] == 200
        _until(server, lambda s: _done(s) >= 1)
        assert server.request("/api/scan/stop", data={})[0] == 200
        stopped = _until(server, lambda s: not s["running"] and s["exit_code"] is not None)
        assert stopped["exit_code"] == 130 and 1 <= _done(stopped) < 4
        assert server.request("/api/scan/start", data={"name": "a", "resume": True})[0] == 200
        ended = _until(server, lambda s: not s["running"] and s["exit_code"] is not None, timeout=600)
        assert ended["exit_code"] == 0 and _done(ended) == 4 and "mesh.ply" in ended["files"]
    finally:
        server.stop()


def _children(pid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(d))
            except OSError:
                pass
    return out


def test_a_server_killed_mid_scan_leaves_a_session_resume_completes_byte_identical(tmp_path):
    server = start_ui(tmp_path)
    try:
        assert server.request("/api/scan/start", data={"name": "b", "views": 3})[0] == 200
        _until(server, lambda s: _done(s) >= 1)
        children = _children(server.proc.pid)
        os.kill(server.proc.pid, signal.SIGKILL)            # no clean-up of its own
        server.proc.wait()
        deadline = time.monotonic() + 120
        while any(os.path.exists(f"/proc/{c}") and open(f"/proc/{c}/stat").read().split()[2] != "Z"
                  for c in children) and time.monotonic() < deadline:
            time.sleep(0.2)                                 # the scan got Ctrl-C: it finishes its view and ends
    finally:
        server.stop()
    session = json.loads((tmp_path / "b" / "session.json").read_text())
    assert any(v["state"] != "done" for v in session["views"])
    run = lambda *a: subprocess.run([sys.executable, "-m", "rangekit", "-q", "scan", *a], capture_output=True,
                                    text=True, stdin=subprocess.DEVNULL, timeout=900)
    resumed = run("--resume", str(tmp_path / "b"))
    assert resumed.returncode == 0, resumed.stderr
    whole = run("--out", str(tmp_path / "whole"), "--views", "3", "--object", "lumpy")
    assert whole.returncode == 0, whole.stderr
    for name in ("mesh.ply", "mesh_watertight.ply", "poses.json"):
        assert (tmp_path / "b" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name
