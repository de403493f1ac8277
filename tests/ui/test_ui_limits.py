"""The server stays up and answers whatever a local program sends (issue 48): a thousand unfinished requests, a
100 MB body, JSON nested 100,000 deep, wrong types in every field, names a folder cannot take, a folder name that
is not UTF-8, a jog while others ask, a stop right after a start. Each against the real ``rangekit ui``: no
traceback, no hang, no 500."""

from __future__ import annotations

import json
import os
import socket
import threading
import time

import pytest

from support.ui_server import serving


server = pytest.fixture(scope="module", name="server")(serving)


def _raw(server, head: bytes, body: bytes = b"", read: bool = True) -> bytes:
    port = int(server.base.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:
        try:
            s.sendall(head + body)
        except (BrokenPipeError, ConnectionResetError):     # refused before the whole body was sent
            pass
        reply = b""
        s.settimeout(2.0)
        while read and not (b"\r\n\r\n" in reply and reply.rstrip().endswith(b"}")):
            try:
                part = s.recv(65536)
            except (socket.timeout, ConnectionResetError):
                break
            if not part:
                break
            reply += part
        return reply


def test_a_thousand_unfinished_requests_leave_the_server_answering(server):
    port = int(server.base.rsplit(":", 1)[1])
    held = []
    try:
        for _ in range(1100):
            s = socket.create_connection(("127.0.0.1", port), timeout=30)
            s.sendall(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\n")       # never finished
            held.append(s)
        started = time.monotonic()
        status, body, _ = server.request("/api/status")
        assert status == 200 and time.monotonic() - started < 5
        # The server closed the ones over its cap at once, and the rest within its header deadline.
        time.sleep(12)
        open_ = 0
        for s in held:
            s.settimeout(0.01)
            try:
                open_ += s.recv(1) != b""
            except socket.timeout:
                open_ += 1
            except OSError:
                pass
        assert open_ == 0
    finally:
        for s in held:
            s.close()
    assert server.request("/api/status")[0] == 200


def test_a_body_over_the_limit_is_refused_before_it_is_read(server):
    head = (f"POST /api/pattern HTTP/1.1\r\nHost: {server.base[7:]}\r\nOrigin: {server.base}\r\n"
            f"Content-Type: application/json\r\nX-Rangekit-Token: {server.token}\r\n").encode()
    started = time.monotonic()
    reply = _raw(server, head + b"Content-Length: 100000000\r\n\r\n", b'{"name": ')      # 100 MB announced
    assert reply.startswith(b"HTTP/1.1 413") and b"at most 1048576 bytes" in reply
    assert time.monotonic() - started < 5
    # Chunked, no length: refused as soon as the stream passes the limit.
    chunk = b"x" * 65536
    body = b"".join(b"%x\r\n%s\r\n" % (len(chunk), chunk) for _ in range(20)) + b"0\r\n\r\n"
    reply = _raw(server, head + b"Transfer-Encoding: chunked\r\n\r\n", body)
    assert reply.startswith(b"HTTP/1.1 413"), reply[:200]
    status, reply, _ = server.request("/api/pattern", raw=b"[" * 100_000 + b"]" * 100_000)
    assert status == 400 and json.loads(reply) == {"error": "request: JSON nested too deep"}


@pytest.mark.parametrize("path, body, words", [
    ("/api/scan/pause", {"paused": "no"}, "paused: expected true or false, found 'no'"),
    ("/api/scan/start", {"name": ["x"], "views": 2}, "name: expected a string, found ['x']"),
    ("/api/scan/start", {"name": "s", "views": 2, "resume": "yes"}, "resume: expected true or false, found 'yes'"),
    ("/api/scan/start", {"name": "s", "views": 2.5}, "views: expected a whole number 2-720, found 2.5"),
    ("/api/scan/start", {"name": "s", "view": 2}, "scan: 'view': not a field here; expected name, views, resume"),
    ("/api/pattern", {"name": 3}, "name: expected a string, found 3"),
    ("/api/pattern", {}, "name: missing; pattern needs it"),
    ("/api/turntable", {"degrees": 1e9}, "degrees: expected a number -360 to 360, found 1000000000.0"),
    ("/api/turntable", {"degrees": True}, "degrees: expected a number -360 to 360, found True"),
    ("/api/turntable", {"home": "yes"}, "home: expected true or false, found 'yes'"),
    ("/api/camera", {"exposure_us": [1]}, "camera: exposure_us: expected a number or 'auto', found [1]"),
    ("/api/calibrate/start", {"poses": "12"}, "poses: expected a whole number 3-60, found '12'"),
    ("/api/calibrate-recorded/start", {"captures": ["a"]}, "captures: expected a string, found ['a']"),
    ("/api/calibrate-recorded/start", {"captures": "x", "pattern": {"a": 1}}, "pattern: expected a string"),
    ("/api/register/start", {"files": "a.ply"}, "files: expected a list of at most 2000 strings, found 'a.ply'"),
    ("/api/register/save", {"name": None}, "name: expected a string, found None"),
    ("/api/sessions/x/process", {"report": "no"}, "report: expected true or false, found 'no'"),
    ("/api/sessions/x/export", {"format": 1}, "format: expected a string, found 1"),
    ("/api/ticket", {"path": 1}, "path: expected a string, found 1"),
])
def test_every_field_is_type_checked_with_a_400_naming_it(server, path, body, words):
    status, reply, _ = server.request(path, data=body)
    assert status == 400 and json.loads(reply)["error"].startswith(words), reply


@pytest.mark.parametrize("name, words", [
    ("x" * 255, "name: 255 characters; at most 100"),
    (".registering", "name: '.registering': begins with '.'"),
    ("a\\b", "name: 'a\\\\b': '\\\\' not allowed"),
    ("a b", "name: 'a b': ' ' not allowed"),
    ("", "name: empty"),
])
def test_a_scan_name_a_folder_cannot_take_is_refused_before_the_scan_starts(server, name, words):
    status, reply, _ = server.request("/api/scan/start", data={"name": name, "views": 2})
    assert status == 400 and json.loads(reply)["error"].startswith(words), reply
    assert json.loads(server.request("/api/scan")[1])["name"] is None
    status, reply, _ = server.request(f"/api/sessions/{'y' * 300}/export", data={"format": "obj"})
    assert status == 400 and "Traceback" not in reply.decode()


def test_a_scan_into_a_folder_already_there_is_refused_and_the_folder_kept(server):
    (server.sessions / "mine").mkdir()
    (server.sessions / "mine" / "notes.txt").write_text("keep")
    status, reply, _ = server.request("/api/scan/start", data={"name": "mine", "views": 2})
    assert status == 400 and json.loads(reply)["error"].startswith("name: mine exists under the sessions folder"), reply
    assert json.loads(server.request("/api/scan")[1])["name"] is None
    assert [p.name for p in (server.sessions / "mine").iterdir()] == ["notes.txt"]


def test_a_folder_name_that_is_not_utf8_is_skipped_and_said(server):
    folder = os.path.join(os.fsencode(server.sessions), b"caf\xe9")
    os.makedirs(folder)
    with open(os.path.join(folder, b"session.json"), "w") as f:
        f.write("{}")
    with open(os.path.join(folder, b"cloud.ply"), "w") as f:
        f.write("ply\n")
    status, body, _ = server.request("/api/sessions")
    assert status == 200
    listing = json.loads(body)
    assert listing["skipped"] == ["caf\\xe9: skipped: its name is not UTF-8; rename it to open it here"]
    assert all("caf" not in s["name"] for s in listing["sessions"])
    status, body, _ = server.request("/api/register/clouds")
    assert status == 200 and json.loads(body)["clouds"] == []


def test_status_answers_at_once_while_the_turntable_turns(server):
    jog = {}
    thread = threading.Thread(target=lambda: jog.update(reply=server.request("/api/turntable", data={"degrees": 90})))
    thread.start()
    time.sleep(0.5)
    started = time.monotonic()
    status, body, _ = server.request("/api/status")
    took = time.monotonic() - started
    thread.join()
    assert status == 200 and took < 0.5 and json.loads(body)["rig"]["turntable"]["turning"]
    assert jog["reply"][0] == 200
    assert server.request("/api/turntable", data={"home": True})[0] == 200


def test_a_pause_then_a_stop_right_after_a_start_ends_without_a_traceback(server):
    for k in range(8):
        assert server.request("/api/scan/start", data={"name": f"quick{k}", "views": 2})[0] == 200
        server.request("/api/scan/pause", data={"paused": True})
        server.request("/api/scan/stop", data={})
        deadline = time.monotonic() + 120
        while (state := json.loads(server.request("/api/scan")[1]))["running"] and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not state["running"] and state["exit_code"] == 130, state
        assert not any("Traceback" in line or "KeyboardInterrupt" in line for line in state["log"]), state["log"]


def test_the_form_s_ranges_and_defaults_are_the_options_own(server):
    """``GET /api/options``: the Scan form's ranges and defaults, read from ScanOptions and ProcessOptions (issue 49),
    the ones the command line's --views and the scan's check use."""
    from rangekit._runtime.option_fields import specs
    from rangekit.app.scan.options import SCAN_DEFAULTS, ScanOptions

    status, body = server.request("/api/options")[:2]
    views, s = json.loads(body)["scan"]["views"], specs(ScanOptions)["views"]
    assert status == 200 and (views["min"], views["max"], views["default"]) == (s.lo, s.hi, SCAN_DEFAULTS["views"])
    status, body = server.request("/api/scan/start", data={"name": "s", "views": s.hi + 1})[:2]
    assert status == 400 and json.loads(body)["error"] == f"views: expected a whole number {s.lo}-{s.hi}, found {s.hi + 1}"


def test_each_refusal_is_logged_once(server):
    """(Last in this module: the log of all the above.)"""
    log = server.stop()
    assert "Traceback" not in log and len(log) < 5000, log[-3000:]
    assert log.count("too many connections") <= 1 and log.count("did not arrive within") <= 1

