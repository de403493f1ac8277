"""Pages that come and go while a scan runs (issue 37): the scan is the server's child, not the page's, so a page
that closes neither stops it nor loses a frame of it; a page opened later shows it where it is; two pages open at
once show the same progress. Real Chromium pages, a real scan in real time on the simulator.

Every read of a page waits for what the page can only show after an event has come (the pages change on events,
never on a clock): a browser that starts slowly on a loaded machine (a page opened 60 s late, a replay folded over
several renders) makes the test wait, never read a page that has not caught up yet."""

from __future__ import annotations

import json
import threading
import time

import pytest

from support.chromium import chromium_paths, open_page
from support.sessions import frame_paths
from support.ui_server import start_ui

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                 "chromium chromium-driver (`make test` installs them when run as root)")]

_PROGRESS = ("const t = document.getElementById('scan-state').textContent;"
             "const m = t.match(/([0-9]+) of ([0-9]+) views taken, ([0-9]+) decoded/);"
             "return m ? {taken: +m[1], views: +m[2], decoded: +m[3], shown: window.rangekitScan3d.count} : null;")


def _progress_at_least(taken: int, shown: int) -> str:
    """The page's progress once it shows the scan's views (its ScanStarted folded in), at least ``taken`` views
    taken and ``shown`` drawn; null before."""
    return (f"const p = (() => {{{_PROGRESS}}})();"
            f"return p && p.views > 0 && p.taken >= {int(taken)} && p.shown >= {int(shown)} ? p : null;")


#: What a page shows of the scan and of its events socket (said when a wait for it fails).
_DESCRIBE = ("const c = window.rangekitEvents || {}, s = window.rangekitScanView || {};"
             "return {text: document.getElementById('scan-state').textContent, session: c.session ?? null,"
             " offset: c.offset, received: c.received, connects: c.connects, socket: c.socket ? c.socket.readyState : null,"
             " name: s.name, total: s.total, views: s.views ? s.views.size : null, launched: s.launched,"
             " exit: s.exitCode, hash: location.hash, drawn: window.rangekitScan3d ? window.rangekitScan3d.count : null};")
#: The page follows the server's events: its socket has brought the server's first message (no job yet here).
_FOLLOWING = "return window.rangekitEvents.session !== undefined && window.rangekitScan3d !== undefined;"
#: Seconds a page may take to show what the server already knows (a browser on a loaded machine: generous; the
#: reads return as soon as the page shows it).
_CATCH_UP_S = 300


def _scan_state(server) -> dict:
    return json.loads(server.request("/api/scan")[1])


def test_pages_closing_opening_and_side_by_side_leave_the_scan_alone(tmp_path):
    sessions = tmp_path / "sessions"
    sessions.mkdir()
    server = start_ui(sessions)
    first_closed = threading.Event()
    results: dict = {}
    following = {"a": threading.Event(), "b": threading.Event()}
    started = threading.Event()

    def watch(name: str, stop_when, url_hash: str = "#scan"):
        def interact(page):
            page.execute(f"location.hash = '{url_hash}';")
            page.until(_FOLLOWING, timeout=_CATCH_UP_S)
            following[name].set()
            if not started.wait(_CATCH_UP_S):
                return []
            seen = []
            while not stop_when():
                progress = page.execute(_PROGRESS)
                if progress:
                    seen.append((time.monotonic(), progress))
                time.sleep(0.25)
            if name == "b":    # the scan ended: the page shows its last views once their events came
                seen.append((time.monotonic(), page.until(_progress_at_least(4, 3), timeout=_CATCH_UP_S,
                                                                describe=_DESCRIBE)))
            return seen
        try:
            results[name] = open_page(server.url, width=1200, height=900, timeout_s=900, interact=interact)["interaction"]
        except Exception as exc:  # noqa: BLE001 - reported by the assertions below
            results[name] = exc

    try:
        # Page A: open, then closed once the first view is decoded. Page B: open from the start to the end. Both
        # follow the server before the scan starts (a browser may start slower than the scan runs).
        decoded = lambda k: sum(v["decoded"] for v in _scan_state(server)["views"]) >= k   # noqa: E731
        ended = lambda: not _scan_state(server)["running"]                                  # noqa: E731
        a = threading.Thread(target=watch, args=("a", lambda: decoded(1) or ended()))
        b = threading.Thread(target=watch, args=("b", ended))
        a.start()
        b.start()
        pages_open = all(following[k].wait(_CATCH_UP_S + 60) for k in "ab")
        status, body, _ = server.request("/api/scan/start", data={"name": "s", "views": 4})
        started.set()
        assert status == 200, body
        a.join()
        first_closed.set()
        closed_at = _scan_state(server)
        # Page C: opened after A went away, while the scan runs: it shows the scan where it is.
        c_seen = {}

        def reopen(page):
            page.execute("location.hash = '#scan';")
            # the page shows the views the server had taken when it opened (its replay folded in), no fewer
            c_seen["before"] = _scan_state(server)
            taken_before = sum(v["done"] for v in c_seen["before"]["views"])
            c_seen["first"] = page.until(_progress_at_least(taken_before, 0), timeout=_CATCH_UP_S,
                                         describe=_DESCRIBE)
            c_seen["server"] = _scan_state(server)
            c_seen["drawn"] = page.until("return window.rangekitScan3d.count >= "
                                           f"{sum(v['decoded'] for v in c_seen['server']['views'])} && "
                                           "window.rangekitScan3d.count;", timeout=_CATCH_UP_S)
            return c_seen
        open_page(server.url, width=1200, height=900, timeout_s=300, interact=reopen)
        b.join(timeout=900)
        final = _scan_state(server)
    finally:
        server.stop()
    assert not isinstance(results.get("a"), Exception) and not isinstance(results.get("b"), Exception), results
    assert pages_open, "pages A and B never followed the server's events"
    # Closing page A stopped nothing: the scan ran on to its end, every view taken, decoded and meshed.
    assert closed_at["running"] and final["exit_code"] == 0, (closed_at, final["log"][-5:])
    assert all(v["done"] and v["decoded"] for v in final["views"]) and len(final["views"]) == 4
    folder = sessions / "s"
    per_view = {len(frame_paths(folder, f"{v.name}/*")) for v in folder.glob("view_*")}
    assert len(per_view) == 1 and len(frame_paths(folder)) == 4 * per_view.pop() > 4 and (folder / "mesh.ply").is_file()
    # Page C showed the scan where it was when it opened: the server's views taken, its decoded views drawn.
    first, server_then = c_seen["first"], c_seen["server"]
    assert first["views"] == 4 and abs(first["taken"] - sum(v["done"] for v in server_then["views"])) <= 1
    assert first["taken"] >= sum(v["done"] for v in c_seen["before"]["views"])
    assert c_seen["drawn"] >= sum(v["decoded"] for v in closed_at["views"]) >= 1
    # Pages A and B, open at once, showed the same progress: at each moment both were read, their counts agree
    # to within the one view that can finish between two reads a quarter of a second apart.
    a_seen, b_seen = results["a"], results["b"]
    assert len(a_seen) >= 3 and len(b_seen) >= len(a_seen)
    for t, pa in a_seen:
        pb = min(b_seen, key=lambda item: abs(item[0] - t))[1]
        assert abs(pa["taken"] - pb["taken"]) <= 1 and abs(pa["decoded"] - pb["decoded"]) <= 1, (pa, pb)
    # ... and B followed the scan to its end.
    assert b_seen[-1][1]["taken"] == 4 and b_seen[-1][1]["shown"] >= 3
