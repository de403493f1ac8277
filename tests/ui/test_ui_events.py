"""The web app follows a scan only through its events (issue 49, 2): the session's events.jsonl over /ws/events.
The disk poller and the log reader are gone; a real browser shows every view as it is decoded, from the events
alone (the page never asks GET /api/scan); a page whose socket drops reconnects and replays from its offset,
nothing twice, nothing missed. Real headless Chromium, the real server and a real scan in real time."""

from __future__ import annotations

import json
import time

import pytest
from websockets.sync.client import connect

from support.chromium import chromium_paths, open_page
from support.ui_server import start_ui

_SEEN = ("const s = window.rangekitScanView, v = [...s.views.values()];"
         "return {taken: v.filter((x) => x.done).length, decoded: v.filter((x) => x.decoded).length, total: s.total,"
         " shown: window.rangekitScan3d ? window.rangekitScan3d.count : 0, exit: s.exitCode,"
         " text: document.getElementById('scan-state').textContent,"
         " received: window.rangekitEvents.received, connects: window.rangekitEvents.connects,"
         " polled: performance.getEntriesByType('resource').filter((e) => /\\/api\\/scan$/.test(e.name)).length};")


def test_the_disk_poller_and_the_log_reader_are_gone():
    import rangekit.ui.jobs.scan as scan_job

    assert not hasattr(scan_job, "session_state")           # the 700 ms disk poll of session.json and view folders
    import inspect

    source = open(scan_job.__file__).read()
    assert "cloud.json" not in source and "Session.load" not in source and "iterdir" not in source
    # GET /api/scan is the fold of the job's events; the child's lines are kept for people, never parsed
    assert "self._fold()" in inspect.getsource(scan_job.ScanJob.snapshot)
    assert "self.log" not in inspect.getsource(scan_job.ScanJob._fold)


def _events(server, query: str = "") -> list:
    """The /ws/events messages until the socket has been quiet for a second."""
    ticket = server.ticket("/ws/events")
    out = []
    with connect(server.base.replace("http://", "ws://") + f"/ws/events?ticket={ticket}{query}",
                 origin=server.base, open_timeout=20) as ws:
        while True:
            try:
                out.append(json.loads(ws.recv(timeout=1.0)))
            except TimeoutError:
                return out


def test_the_events_socket_needs_a_ticket_and_says_when_there_is_no_job(tmp_path):
    server = start_ui(tmp_path)
    try:
        assert _events(server) == [{"session": None, "launch": 0, "start": 0, "offset": 0}]
        from websockets.exceptions import InvalidStatus

        with pytest.raises(InvalidStatus):
            connect(server.base.replace("http://", "ws://") + "/ws/events", origin=server.base, open_timeout=20)
        with pytest.raises(InvalidStatus):
            connect(server.base.replace("http://", "ws://") + f"/ws/events?ticket={server.ticket('/ws/events')}",
                    origin="http://evil.example", open_timeout=20)
    finally:
        server.stop()


pytestmark_browser = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                        "chromium chromium-driver (`make test` installs them when run as root)")


@pytest.mark.slow
@pytestmark_browser
def test_a_browser_shows_every_view_as_it_is_decoded_from_the_events_and_replays_after_a_drop(tmp_path):
    sessions = tmp_path / "sessions"
    sessions.mkdir()
    server = start_ui(sessions)
    try:
        def scan(page):
            page.execute("location.hash = '#scan';")
            page.until("return window.rangekitEvents.session === null;")
            page.execute("const f = document.getElementById('scan-form'); f.name.value = 'ev';"
                         "f.views.value = '4'; document.getElementById('scan-start').click();")
            seen, dropped = [], None
            deadline = time.monotonic() + 900
            while time.monotonic() < deadline:
                now = page.execute(_SEEN)
                seen.append(now)
                if dropped is None and now["decoded"] >= 1:        # the socket drops: the page reconnects
                    page.execute("window.rangekitEvents.socket.close();")
                    dropped = now["received"]
                if now["exit"] is not None:
                    break
                time.sleep(0.25)
            final = page.until("const s = window.rangekitScanView;"
                               "return window.rangekitScan3d.vertices > 0 && `exit ${s.exitCode}`;", timeout=120)
            return seen, dropped, final, page.execute(_SEEN)

        seen, dropped, final, last = open_page(server.url, width=1200, height=900, timeout_s=1200,
                                               interact=scan)["interaction"]
    finally:
        server.stop()
    lines = (sessions / "ev" / "events.jsonl").read_text().splitlines()
    kinds = [json.loads(line)["type"] for line in lines]
    assert final == "exit 0" and kinds[-1] == "JobExited"
    # Every view shown as it was decoded: the page's count of decoded views rose one at a time with the events,
    # while views were still to take, and all four were drawn; the page never polled GET /api/scan.
    decoded_counts = sorted({s["decoded"] for s in seen})
    assert decoded_counts[-1] == 4 and set(range(1, 5)) <= set(decoded_counts) | {4}, decoded_counts
    assert any(s["decoded"] >= 1 and s["taken"] < 4 for s in seen), seen[:5]
    assert last["shown"] == 4 and last["text"].startswith("ev: ended (exit 0), 4 of 4 views taken, 4 decoded")
    assert all(s["polled"] == 0 for s in seen) and last["polled"] == 0
    # The drop: the page came back asking for its session from its offset; it got every line once.
    assert dropped is not None and len(last["connects"]) >= 2
    again = last["connects"][1]
    assert again["session"] == "ev" and again["offset"] > 0
    assert last["received"] == len(lines)


@pytest.mark.slow
def test_a_reconnecting_socket_replays_from_its_offset_and_another_session_from_the_start(tmp_path):
    server = start_ui(tmp_path)
    try:
        assert server.request("/api/scan/start", data={"name": "r", "views": 2})[0] == 200
        deadline = time.monotonic() + 600
        while json.loads(server.request("/api/scan")[1])["running"] and time.monotonic() < deadline:
            time.sleep(0.5)
        whole = _events(server)
        hello, rest = whole[0], whole[1:]
        assert hello["session"] == "r" and hello["offset"] == 0 and rest[-1]["event"]["type"] == "JobExited"
        middle = rest[len(rest) // 2]["offset"]
        replay = _events(server, f"&session=r&offset={middle}")
        assert replay[0]["offset"] == middle and replay[1:] == [m for m in rest if m["offset"] > middle]
        assert _events(server, f"&session=other&offset={middle}") == whole      # not this session: from 0
    finally:
        server.stop()


def test_a_scan_refused_before_it_made_its_folder_says_so_on_the_events_socket(tmp_path):
    """No folder, so no events file to hold its JobExited: the socket's job message carries it (the page would
    otherwise show the scan running for ever)."""
    import trimesh

    sessions = tmp_path / "sessions"
    sessions.mkdir()
    mesh = tmp_path / "ball.ply"
    trimesh.creation.icosphere(subdivisions=2, radius=0.05).export(mesh)
    server = start_ui(sessions, "--object", str(mesh))
    try:
        mesh.unlink()          # the scan child's --object is gone: it refuses before it makes its folder
        status, body, _ = server.request("/api/scan/start", data={"name": "gone", "views": 2})
        assert status == 200, body
        for _ in range(600):        # a hang guard, not a speed figure: the child refuses at once
            if not json.loads(server.request("/api/scan")[1])["running"]:
                break
            time.sleep(0.2)
        state = json.loads(server.request("/api/scan")[1])
        head = _events(server)[0]
    finally:
        server.stop()
    assert not state["running"] and state["exit_code"] not in (None, 0), state
    assert head["session"] == "gone" and head["exited"]["type"] == "JobExited", head
    assert head["exited"]["exit_code"] == state["exit_code"] and head["exited"]["last_lines"], head
    assert not (sessions / "gone").exists()
