"""Nobody else gets in (issue 37): the token on every request and WebSocket, the app's own origin and host,
paths confined to the sessions folder. Each against the real server, ``rangekit ui`` on 127.0.0.1."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from support.ui_server import start_ui
from rangekit.cli.ui import _is_loopback
from rangekit.ui.paths import PathRefused, confined


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = start_ui(tmp_path_factory.mktemp("sessions"))
    yield s
    s.stop()


def test_the_page_loads_without_the_token_and_sets_no_cookie(server):
    """The page and its scripts are package data: served without the token (a reloaded tab, its token in
    sessionStorage, must load), never with a cookie (every port of 127.0.0.1 would receive it). A wrong ?token=
    is refused at once. (Issue 37 kept the token as a cookie: issue 48 removed it.)"""
    status, body, headers = server.request("/", token=None)
    assert status == 200 and b"<canvas" in body and "set-cookie" not in {k.lower() for k in headers}
    status, body, headers = server.request("/", token="query")
    assert status == 200 and "set-cookie" not in {k.lower() for k in headers}
    status, body, _ = server.request("/?token=not-the-token", token=None)
    assert status == 403 and b"token missing or wrong" in body
    assert server.request("/static/app.js", token=None)[0] == 200


@pytest.mark.parametrize("path", ["/api/status", "/api/sessions", "/api/check/figure.png", "/api/scan", "/nowhere"])
def test_every_api_route_needs_the_token_in_its_header(server, path):
    assert server.request(path, token=None)[0] == 403
    assert server.request(path, token="x" * 43)[0] == 403
    assert server.request(path, token="query")[0] == 403          # never in the URL: it would end in logs
    assert server.request(path, token=None, headers={"Cookie": f"rangekit_token={server.token}"})[0] == 403
    assert server.request(path)[0] in (404 if path in ("/nowhere", "/api/check/figure.png") else 200,)


def test_a_foreign_host_header_is_refused(server):
    """A page of another site whose name was made to resolve to 127.0.0.1 (DNS rebinding) sends its own Host."""
    status, body, _ = server.request("/api/status", headers={"Host": "rebind.example:80"})
    assert status == 403 and b"host" in body


def _ws(server, origin: str | None, ticket: str | None):
    query = "" if ticket is None else f"?ticket={ticket}"
    return connect(server.base.replace("http://", "ws://") + "/ws/live" + query, origin=origin, open_timeout=20)


def test_a_websocket_needs_the_apps_origin_and_a_single_use_ticket(server):
    for origin in ("http://evil.example", "null", None, server.base.replace("127.0.0.1", "127.0.0.2")):
        with pytest.raises(InvalidStatus) as refused:
            _ws(server, origin, server.ticket("/ws/live")).recv(timeout=5)
        assert refused.value.response.status_code == 403
    with pytest.raises(InvalidStatus):
        _ws(server, server.base, None).recv(timeout=5)      # its own origin, no ticket
    with pytest.raises(InvalidStatus):
        _ws(server, server.base, server.token).recv(timeout=5)      # the token is no ticket
    spent = server.ticket("/ws/live")
    with _ws(server, server.base, spent) as ws:
        ws.recv(timeout=30)
    with pytest.raises(InvalidStatus):
        _ws(server, server.base, spent).recv(timeout=5)     # single use
    status, body, _ = server.request("/api/ticket", data={"path": "/api/status"})
    assert status == 400 and json.loads(body)["error"].startswith("path: '/api/status': no ticket for it")


def test_the_apps_own_websocket_streams_frames_that_change(server):
    with _ws(server, server.base, server.ticket("/ws/live")) as ws:
        frames, figures = [], None
        while len(frames) < 2:
            msg = ws.recv(timeout=30)
            if isinstance(msg, str):
                figures = json.loads(msg)
            else:
                frames.append(msg)
    assert all(f[:2] == b"\xff\xd8" for f in frames) and frames[0] != frames[1]   # JPEGs, new noise each
    assert figures["width"] == 1280 and figures["saturated_percent"] >= 0 and figures["focus"] > 0


def test_bad_input_gets_the_one_line_error_and_the_server_lives_on(server):
    # (issue 49: the one error handler adds the request field the line names, as jupyter_server's write_error)
    for path, data, words, field in [
            ("/api/pattern", {"name": "nonsense"}, "pattern 'nonsense': unknown; expected one of", None),
            ("/api/turntable", {"degrees": "ten"}, "degrees: expected a number -360 to 360, found 'ten'", "degrees"),
            ("/api/turntable", {"degrees": 1000}, "degrees: expected a number -360 to 360, found 1000", "degrees"),
            ("/api/turntable", [1, 2], "request: expected a JSON object", None)]:
        status, body, _ = server.request(path, data=data)
        assert status == 400 and list(json.loads(body)) == ["error"] + ([] if field is None else ["field"])
        assert json.loads(body)["error"].startswith(words) and json.loads(body).get("field") == field
        assert "Traceback" not in body.decode() and "\n" not in json.loads(body)["error"]
    status, body, _ = server.request("/api/turntable", data={"degrees": 30})
    # The simulated Horus board over its pty stops on a microstep (3200 a turn: 0.1125 deg), as a real one does.
    assert status == 200 and json.loads(body)["rig"]["turntable"]["angle_deg"] == pytest.approx(30.0, abs=0.06)
    assert json.loads(body)["rig"]["last_reply"].startswith("turntable at 30.04 deg (")   # 267 microsteps
    status, body, _ = server.request("/api/turntable", data={"home": True})
    assert json.loads(body)["rig"]["turntable"]["angle_deg"] == pytest.approx(0.0)


def test_a_port_in_use_is_named_in_one_line(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        run = subprocess.run([sys.executable, "-m", "rangekit", "ui", "--port", str(port), "--sessions", str(tmp_path)],
                             capture_output=True,
                             text=True, timeout=120, stdin=subprocess.DEVNULL, env=dict(os.environ))
    assert run.returncode == 1 and "Traceback" not in run.stderr
    assert f"--host 127.0.0.1 --port {port}: is in use by another program; choose another with --port" in run.stderr
    assert not any(tmp_path.iterdir())     # said before anything was written


def test_only_loopback_hosts_go_without_a_warning():
    assert all(_is_loopback(h) for h in ("127.0.0.1", "127.0.0.2", "localhost", "::1"))
    assert not any(_is_loopback(h) for h in ("0.0.0.0", "192.168.1.10", "::", "example.org"))


def test_paths_are_confined_to_the_sessions_folder(tmp_path):
    root = tmp_path / "sessions"
    (root / "scan1").mkdir(parents=True)
    (tmp_path / "secret").mkdir()
    (root / "out").symlink_to(tmp_path / "secret")
    (root / "inside").symlink_to(root / "scan1")
    assert confined(root, "scan1") == (root / "scan1").resolve()
    assert confined(root, "inside") == (root / "scan1").resolve()
    assert confined(root, "") == root.resolve()
    for name, words in [("../secret", "'..' leads out"), ("scan1/../../secret", "'..' leads out"),
                        ("/etc/passwd", "absolute"), ("~root", "absolute"), ("out", "a link out"),
                        ("out/x", "a link out"), ("a\\..\\b", "'/' separated"), ("a\x00b", "'/' separated")]:
        with pytest.raises(PathRefused, match=words):
            confined(root, name)


def test_camera_controls_are_written_into_the_rig_file_and_change_the_frames(server, tmp_path):
    rig_file = Path(json.loads(server.request("/api/status")[1])["rig"]["rig_file"])
    before = json.loads(rig_file.read_text())

    def dark_percent() -> float:
        """The figures of the 4th frame after connecting (the first two may have been taken before a change)."""
        with _ws(server, server.base, server.ticket("/ws/live")) as ws:
            got = []
            while len(got) < 4:
                msg = ws.recv(timeout=30)
                if isinstance(msg, str) and "seq" in msg:
                    got.append(json.loads(msg))
        return got[-1]["dark_percent"]

    dark_before = dark_percent()
    status, body, _ = server.request("/api/camera", data={"exposure_us": 8000, "iso": 100})
    assert status == 200, body
    after = json.loads(rig_file.read_text())
    assert after["capture"]["camera"] == {**before["capture"].get("camera", {}), "exposure_us": 8000, "iso": 100}
    assert {k: v for k, v in after.items() if k != "capture"} == {k: v for k, v in before.items() if k != "capture"}
    assert dark_percent() > dark_before + 1.0    # a quarter of the default 33 ms exposure: more pixels too dark
    # A bad value: the rig file's own one-line error naming the field, and the file untouched.
    status, body, _ = server.request("/api/camera", data={"exposure_us": "abc"})
    assert status == 400 and json.loads(body)["error"].startswith(f"{rig_file}: capture.camera.exposure_us:")
    assert json.loads(rig_file.read_text()) == after
    status, body, _ = server.request("/api/camera", data={"shutter": 5})
    assert status == 400 and "camera: shutter: not a control here" in json.loads(body)["error"]
    assert server.request("/api/camera", data={"exposure_us": 33333})[0] == 200


@pytest.mark.parametrize("body, words", [       # (issue 48: a name's errors begin with "name:", shown by its field)
    ({"name": "../outside", "views": 6}, "name: '../outside': begins with '.'; begin with a letter or a digit"),
    ({"name": "/tmp/x", "views": 6}, "name: '/tmp/x': begins with '/'"),
    ({"name": "a/b", "views": 6}, "name: 'a/b': '/' not allowed"),
    ({"name": "s", "views": "six"}, "views: expected a whole number 2-720, found 'six'"),
    ({"name": "s", "views": 1}, "views: expected a whole number 2-720, found 1"),
])
def test_a_scan_is_refused_outside_the_sessions_folder_or_with_bad_views(server, body, words):
    status, reply, _ = server.request("/api/scan/start", data=body)
    assert status == 400 and json.loads(reply)["error"].startswith(words)
    assert not json.loads(server.request("/api/scan")[1])["running"]


def test_no_scan_to_stop_and_no_points_out_of_the_sessions_folder(server):
    status, reply, _ = server.request("/api/scan/stop", data={})
    assert status == 400 and json.loads(reply)["error"] == "no scan is running"
    for name in ("..", "%2E%2E", "nowhere"):
        status, reply, _ = server.request(f"/api/sessions/{name}/views/0/points")
        assert status in (400, 404) and b"Traceback" not in reply
