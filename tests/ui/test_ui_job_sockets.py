"""The web app's other jobs followed only through their events (issue 49, 2): the check, the calibrations and the
registration, and the rig's status, sent over ``/ws/jobs`` as they change (the app's notifier,
:mod:`rangekit.ui.jobs.notifier`). A real browser shows their progress and their end with the GET endpoints a page
used to poll made unreachable for it (Chromium's own request blocking); a page that reconnects mid-job is sent the
state it missed; no script of the page runs a timer that asks the server anything. The real server, headless
Chromium."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest
from websockets.sync.client import connect

from support.chromium import chromium_paths, open_page
from support.ui_server import serving

#: The GET endpoints the pages polled on a timer before (issue 49): unreachable for the page in the browser test.
POLLED = ("/api/check", "/api/calibrate", "/api/calibrate-recorded", "/api/register", "/api/status", "/api/scan",
          "/api/sessions")


server = pytest.fixture(scope="module", name="server")(serving)


def _post(server, path, data=None):
    status, body, _ = server.request(path, data=data if data is not None else {})
    assert status == 200, (path, body)
    return json.loads(body)


def _get(server, path):
    return json.loads(server.request(path)[1])


def _socket(server):
    ticket = server.ticket("/ws/jobs")
    return connect(server.base.replace("http://", "ws://") + f"/ws/jobs?ticket={ticket}", origin=server.base,
                   open_timeout=20)


def test_the_static_scripts_run_no_timer_that_asks_the_server():
    from rangekit.ui.routes.page import STATIC

    scripts = sorted(STATIC.glob("*.js"))
    assert {p.name for p in scripts} >= {"check.js", "calibrate.js", "register.js", "sessions.js", "live.js"}
    found = [f"{p.name}:{n}" for p in scripts for n, line in enumerate(p.read_text().splitlines(), 1)
             if "setInterval" in line]
    assert found == []


def test_the_jobs_socket_needs_a_ticket_sends_every_state_then_each_change(server):
    from websockets.exceptions import InvalidStatus

    with pytest.raises(InvalidStatus):
        connect(server.base.replace("http://", "ws://") + "/ws/jobs", origin=server.base, open_timeout=20)
    with pytest.raises(InvalidStatus):
        connect(server.base.replace("http://", "ws://") + f"/ws/jobs?ticket={server.ticket('/ws/jobs')}",
                origin="http://evil.example", open_timeout=20)
    with _socket(server) as ws:
        first = [json.loads(ws.recv(timeout=20)) for _ in range(5)]
        assert [m.get("job") for m in first] == ["check", "calibrate", "recorded", "register", None]
        assert first[0]["snapshot"] == _get(server, "/api/check")
        assert first[3]["snapshot"] == _get(server, "/api/register")
        assert set(first[4]) == {"rig"} and set(first[4]["rig"]) == set(_get(server, "/api/status"))
        assert first[4]["rig"]["rig"]["pattern"] == "white"
        with pytest.raises(TimeoutError):          # nothing changes: nothing is sent
            ws.recv(timeout=1.0)
        _post(server, "/api/pattern", {"name": "checker"})         # another client changes the rig
        assert json.loads(ws.recv(timeout=20))["rig"]["rig"]["pattern"] == "checker"
        _post(server, "/api/pattern", {"name": "white"})
        assert json.loads(ws.recv(timeout=20))["rig"]["rig"]["pattern"] == "white"


def _clouds(folder) -> None:
    """Two clouds of one bumpy patch under ``folder``, the second moved by 3 degrees and a few mm."""
    from rangekit.formats.clouds import save_cloud
    from rangekit.geometry import apply_T, invert_T, make_T
    from rangekit.surface.cloud import PointCloud

    rng = np.random.default_rng(4)
    xy = rng.uniform([-0.04, -0.03], [0.04, 0.03], (2, 8000, 2))
    a, b = (np.column_stack([p, 0.004 * np.sin(70 * p[:, 0]) * np.cos(50 * p[:, 1]) + 0.15 * p[:, 0] + 0.5])
            for p in xy)
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    T_a_b = make_T(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), np.array([0.002, -0.001, 0.0005]))
    folder.mkdir()
    save_cloud(folder / "a.ply", PointCloud(a))
    save_cloud(folder / "b.ply", PointCloud(apply_T(invert_T(T_a_b), b)))


_TEXT = "return document.getElementById(arguments[0]).textContent;"
#: Every request the page's scripts make from now on, recorded (api.js calls the window's fetch).
_RECORD = ("window.asked = []; const fetched = window.fetch;"
           "window.fetch = (url, init) => { window.asked.push(String(url)); return fetched(url, init); };")
_JOBS = "return {connects: window.rangekitEvents.jobConnects, messages: window.rangekitEvents.jobMessages};"


def _block(page, paths) -> None:
    """Chromium refuses the page's requests of exactly these paths (URLPattern syntax: ``/api/check`` blocked,
    ``/api/check/run`` not)."""
    page.cdp("Network.enable")
    page.cdp("Network.setBlockedURLs", {"urlPatterns": [{"urlPattern": f"*://*:*{p}", "block": True} for p in paths]})


pytestmark_browser = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                        "chromium chromium-driver (`make test` installs them when run as root)")


@pytestmark_browser
def test_a_page_follows_the_check_the_calibrations_the_registration_and_the_rig_without_asking(server):
    (server.sessions / "calib" / "seq1").mkdir(parents=True)
    _clouds(server.sessions / "pair")

    def follow(page):
        out = {}
        _block(page, POLLED)
        page.goto(server.url)          # from its first request on, the page cannot reach what it used to poll
        out["blocked"] = page.until("return Promise.all(['/api/status', '/api/check/figure.png'].map((u) => "
                                    "fetch(u).then(() => 'reached', () => 'blocked'))).then((r) => r.join());")
        page.until("return document.getElementById('rig-source').textContent.includes('simulator');")
        page.execute(_RECORD)
        # The rig: a jog by another client shows on the page (a rig event), as the page's own jog does.
        angle = _post(server, "/api/turntable", {"degrees": 10})["rig"]["turntable"]["angle_deg"]
        out["jogged"] = [angle, page.until(f"return document.getElementById('status').textContent"
                                           f".includes('turntable{angle} deg');")]
        # The check, run from the page: running with its progress lines (the rig busy meanwhile), then its result.
        page.execute("location.hash = '#check'; document.getElementById('check-run').click();")
        out["check_running"] = page.until("return document.getElementById('check-state').textContent === 'running'"
                                          " && document.querySelectorAll('#check-progress li').length;", timeout=120)
        out["busy"] = page.until("return document.getElementById('status').textContent.includes('busycheck');")
        page.until("return !document.getElementById('check-apply').disabled;", timeout=300)
        out["check_done"] = [page.execute(_TEXT, "check-state"), page.execute(
            "return document.querySelectorAll('#check-figures tr').length;")]
        out["free"] = page.until("return document.getElementById('status').textContent.includes('busyno');")
        # The recorded calibration: one empty pose folder, refused by the calibration itself; its end shown.
        page.execute("location.hash = '#calibrate';")
        page.until("return document.getElementById('recorded-form').pattern.options.length > 0;")
        page.execute("const f = document.getElementById('recorded-form'); f.captures.value = 'calib/seq*';"
                     "f.pattern.value = 'slstudio:calibration'; f.projector.value = '64x40'; f.out.value = 'r.json';"
                     "document.getElementById('recorded-start').click();")
        out["recorded"] = page.until("const t = document.getElementById('recorded-state').textContent;"
                                     "return t.startsWith('failed') && t;", timeout=120)
        # The wizard: placing, then a capture made by another client while the page's socket is down (no ticket
        # to reopen it: the page cannot reach the server meanwhile); back, the page shows the pose under review.
        page.execute("const f = document.getElementById('calibrate-form'); f.poses.value = '3';"
                     "document.getElementById('calibrate-start').click();")
        page.until("return document.getElementById('calibrate-state').textContent.startsWith('place the board');",
                   timeout=120)
        before = page.execute(_JOBS)
        _block(page, POLLED + ("/api/ticket",))
        page.execute("window.rangekitEvents.jobSocket.close();")
        page.until("return window.rangekitEvents.jobSocket === null;")
        _post(server, "/api/calibrate/capture")
        deadline = time.monotonic() + 120
        while _get(server, "/api/calibrate")["state"] != "review" and time.monotonic() < deadline:
            time.sleep(0.2)
        out["missed"] = page.execute(_TEXT, "calibrate-state")
        _block(page, POLLED)
        out["review"] = page.until("const t = document.getElementById('calibrate-state').textContent;"
                                   "return t.startsWith('keep this pose') && t;", timeout=60)
        out["review_rows"] = page.execute("return document.getElementById('calibrate-poses').textContent;")
        out["reconnected"] = [before, page.execute(_JOBS)]
        page.execute("document.getElementById('calibrate-cancel').click();")
        out["cancelled"] = page.until("const t = document.getElementById('calibrate-state').textContent;"
                                      "return t === 'cancelled' && t;", timeout=120)
        # The registration: two clouds picked in the page, the pair's residual shown, both clouds in 3D.
        page.execute("location.hash = '#register';")
        page.until("return document.querySelectorAll('#register-clouds input').length >= 2;")
        page.execute("for (const v of ['pair/a.ply', 'pair/b.ply'])"
                     "  document.querySelector(`#register-clouds input[value='${v}']`).click();"
                     "document.getElementById('register-form').neighbours.value = '0';"
                     "document.getElementById('register-start').click();")
        out["registered"] = page.until("const t = document.getElementById('register-state').textContent;"
                                       "return t.startsWith('done') && t;", timeout=180)
        out["pairs"] = page.until("return document.querySelectorAll('#register-pairs tr').length;")
        out["drawn"] = page.until("return window.rangekitRegister3d.count === 2 && 2;", timeout=60)
        out["banner"] = page.execute("return document.getElementById('banner').hidden;")
        out["asked"] = page.execute("return window.asked;")
        return out

    out = open_page(server.url, width=1280, height=900, timeout_s=600, interact=follow)["interaction"]
    assert out["blocked"] == "blocked,reached"
    assert out["jogged"][0] == pytest.approx(10, abs=0.1) and out["jogged"][1]
    assert out["check_running"] >= 1 and out["busy"] and out["free"]
    assert out["check_done"][0] == "done" and out["check_done"][1] == 6
    assert "at least 3" in out["recorded"] and "\n" not in out["recorded"]
    # The page missed the capture while its socket was down; reconnected, it was sent the state it missed.
    assert out["missed"].startswith("place the board")
    assert out["review"].startswith("keep this pose") and out["review_rows"].startswith("pose 1kept")
    before, after = out["reconnected"]
    assert after["connects"] == before["connects"] + 1 >= 2 and after["messages"] > before["messages"]
    assert out["cancelled"] == "cancelled" and _get(server, "/api/calibrate")["state"] == "cancelled"
    assert re.match(r"done: RMS [0-9.]+ mm over all pairs", out["registered"]) and out["pairs"] == 2
    assert out["drawn"] == 2 and out["banner"]
    # What the page asked for all along: none of the endpoints it used to poll (nor any twice on a timer).
    assert out["asked"] and not [u for u in out["asked"] if u in POLLED], out["asked"]
