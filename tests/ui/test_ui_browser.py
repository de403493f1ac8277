"""The web app in a real browser (issue 37): headless Chromium (Debian's) opens the URL ``rangekit ui`` printed."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from support.calib_tolerances import outside_tolerances
from support.chromium import chromium_paths, open_page
from support.ui_server import start_ui

pytestmark = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                "chromium chromium-driver (`make test` installs them when run as root)")

_CANVAS = """
const c = document.getElementById('live-canvas');
const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
let red = 0, sum = 0;
for (let i = 0; i < d.length; i += 4) {
  if (d[i] > 200 && d[i + 1] < 60 && d[i + 2] < 60) red++;
  sum = (sum * 31 + d[i] + 7 * d[i + 1]) % 1000000007;
}
return {width: c.width, height: c.height, red: red, sum: sum,
        frames: window.rangekitLive ? window.rangekitLive.frames : 0,
        sat: document.getElementById('fig-sat').textContent, fps: document.getElementById('fig-fps').textContent};
"""


def test_the_live_page_streams_frames_and_marks_a_saturating_object(tmp_path):
    server = start_ui(tmp_path, "--object", "shiny")
    try:
        def look(page):
            page.until("return window.rangekitLive && window.rangekitLive.frames >= 3;")
            first = page.execute(_CANVAS)
            page.until(f"return window.rangekitLive.frames >= {first['frames'] + 3};")
            second = page.execute(_CANVAS)
            page.execute("document.querySelector('[data-name=checker]').click();")
            page.until("return document.querySelector('[data-name=checker]').classList.contains('on');")
            # A non-numeric exposure: the rig file's one-line error next to its field, nothing else changed.
            page.execute("document.querySelector('[name=exposure_us]').value = 'abc';"
                         "document.querySelector('#controls button').click();")
            error = page.until("return document.querySelector('.field-error[data-for=exposure_us]').textContent;")
            return first, second, error

        out = open_page(server.url, width=1280, height=800, timeout_s=120, interact=look,
                        screenshot=tmp_path / "live.png")
        first, second, error = out["interaction"]
    finally:
        server.stop()
    assert (first["width"], first["height"]) == (1280, 1024)
    assert first["sum"] != second["sum"]            # the canvas changed between two reads
    # The shiny object's highlights: 0.4% of the frame at full scale, drawn red (5,000 pixels of 1.3M).
    assert first["red"] > 2000 and second["red"] > 2000
    assert first["sat"].endswith("%") and float(first["sat"].split()[0]) > 0.1
    assert "capture.camera.exposure_us: expected a number" in error and "abc" in error and "\n" not in error
    assert "Traceback" not in error


class _Shots:
    """The pages' screenshots: into the test's folder, and with RANGEKIT_UI_SHOTS=DIR also into DIR as 1000-px
    JPEGs (docs/ui.md's pictures; the command is in docs/ui.md)."""

    def __init__(self, tmp_path):
        self.tmp, self.docs = tmp_path, os.environ.get("RANGEKIT_UI_SHOTS")

    def take(self, page, name: str) -> None:
        png = self.tmp / f"{name}.png"
        page.screenshot(png)
        if self.docs:
            import cv2

            image = cv2.imread(str(png))
            scale = 1000 / image.shape[1]
            Path(self.docs).mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(Path(self.docs) / f"{name}.jpg"), cv2.resize(image, None, fx=scale, fy=scale,
                                                                          interpolation=cv2.INTER_AREA),
                        [cv2.IMWRITE_JPEG_QUALITY, 85])


def _calibrate(page, shots) -> dict:
    """12 simulated poses through the wizard: the board moved once by 'next pose' and once by a drag, one pose
    retaken; returns what the page showed along the way."""
    page.execute("location.hash = '#calibrate';")
    page.execute("const f = document.getElementById('calibrate-form'); f.poses.value = '12';"
                 "document.getElementById('calibrate-start').click();")
    seen = {"corners": 0, "moved": False, "dragged": False, "retaken": False, "hints": set(), "errors": []}
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline:
        c = page.execute("return window.rangekitCalibrate || null;")
        if c is None or c["state"] in ("starting", "capturing", "moving", "turntable"):
            time.sleep(0.2)
            continue
        if c["state"] == "placing":
            board = page.execute("const f = window.rangekitLive && window.rangekitLive.figures;"
                                 "return f && f.board ? f.board.corners.length : 0;")
            seen["corners"] = max(seen["corners"], board)
            if c["pose"] == 1 and not seen["moved"]:
                seen["moved"] = True
                page.execute("document.getElementById('calibrate-next').click();")
                time.sleep(1.0)
                continue
            if c["pose"] == 2 and not seen["dragged"]:
                seen["dragged"] = True
                page.drag(page.element("#calibrate-canvas"), 30, -20)
                time.sleep(1.0)
                continue
            if c["pose"] == 0 and board == 0:
                time.sleep(0.3)            # the first pose: wait for the live corners to show
                continue
            if c["pose"] == 2:
                shots.take(page, "ui-calibrate")
            page.execute("document.getElementById('calibrate-capture').click();")
        elif c["state"] == "review":
            seen["hints"].add(c.get("hint", ""))
            if c["pose"] == 3 and not seen["retaken"]:
                seen["retaken"] = True
                page.execute("document.getElementById('calibrate-retake').click();")
            else:
                page.execute("document.getElementById('calibrate-keep').click();")
        elif c["state"] in ("done", "failed", "cancelled"):
            seen["final"] = c
            shots.take(page, "ui-calibrate-done")
            return seen
        time.sleep(0.3)
    raise AssertionError("the calibration did not finish in the page")


@pytest.mark.slow
def test_the_whole_path_in_a_browser(tmp_path):
    """Check, apply its exposure; calibrate 12 poses; scan 6 views, the first view's points shown before the
    last is taken; the mesh; the Sessions page opens the report; two view clouds registered and saved
    (about 5 minutes: the simulated rig keeps real time)."""
    from rangekit.calib.procedure import compare_rigs
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import default_rig

    sessions = tmp_path / "sessions"
    sessions.mkdir()
    shots = _Shots(tmp_path)
    server = start_ui(sessions, "--object", "shiny")
    try:
        def path(page):
            out = {}
            page.until("return window.rangekitLive && window.rangekitLive.frames >= 40;")   # a steady frame rate shown
            shots.take(page, "ui-live")
            # Check: run, then apply its suggestion with one click.
            page.execute("location.hash = '#check'; document.getElementById('check-run').click();")
            page.until("return !document.getElementById('check-apply').disabled;", timeout=300)
            out["suggested"] = page.execute("return api('/api/check').then(r => r.json()).then(c => c.suggested);")
            page.execute("document.getElementById('check-apply').click();")
            out["applied"] = page.until("const t = document.getElementById('check-error').textContent;"
                                        "return t.startsWith('applied') && t;")
            shots.take(page, "ui-check")
            out["calibration"] = _calibrate(page, shots)
            # Scan: 6 views; the first view's points before the last view is taken.
            page.execute("location.hash = '#scan';")
            page.execute("const f = document.getElementById('scan-form'); f.name.value = 'first';"
                         "f.views.value = '6'; document.getElementById('scan-start').click();")
            page.until("return window.rangekitScan3d && window.rangekitScan3d.count >= 1;", timeout=240)
            out["taken"] = page.execute("return api('/api/scan').then(r => r.json())"
                                        ".then(s => s.views.filter(v => v.done).length);")
            out["shown"] = page.execute("return window.rangekitScan3d.points;")
            shots.take(page, "ui-scan")
            page.until("return document.getElementById('scan-state').textContent.includes('ended (exit 0)');",
                   timeout=600)
            out["count"] = page.execute("return window.rangekitScan3d.count;")
            out["scan_mesh"] = page.until("return window.rangekitScan3d.vertices;", timeout=60)
            shots.take(page, "ui-scan-done")
            # Sessions: the finished session opened from the Scan page's link: its report and its mesh.
            page.execute("document.getElementById('scan-report').click();")
            page.until("return window.rangekitSession3d.vertices > 0;", timeout=60)
            # The report runs sandboxed (its own origin: no contentDocument from here): read inside its frame.
            page.until("return !!document.getElementById('session-report').getAttribute('src');", timeout=60)
            page.frame("#session-report")
            out["report_title"] = page.until("return document.readyState === 'complete' && document.title;",
                                             timeout=60)
            page.frame(None)
            shots.take(page, "ui-sessions")
            # Registration: the first two views' clouds, registered, residuals shown, saved.
            page.execute("location.hash = '#register';")
            page.until("return document.querySelectorAll('#register-clouds input').length >= 2;")
            page.execute("for (const v of ['first/view_000/cloud.ply', 'first/view_001/cloud.ply'])"
                         "  document.querySelector(`#register-clouds input[value='${v}']`).click();"
                         "document.getElementById('register-start').click();")
            page.until("return !document.getElementById('register-save-button').disabled;", timeout=180)
            out["pairs"] = page.execute("return api('/api/register').then(r => r.json()).then(s => s.pairs);")
            shots.take(page, "ui-register")
            page.execute("document.getElementById('register-save').name.value = 'two-views';"
                         "document.getElementById('register-save-button').click();")
            page.until("return document.getElementById('register-state').textContent.includes('saved as two-views');")
            return out

        result = open_page(server.url, width=1400, height=1000, timeout_s=1500, interact=path,
                           screenshot=tmp_path / "last.png")["interaction"]
    finally:
        server.stop()
    # Check: the suggested exposure is the rig file's now.
    rig = load_rig(sessions / "sim-rig.json")
    assert rig.capture["camera"]["exposure_us"] == result["suggested"]["capture.camera.exposure_us"]
    assert result["applied"] == ("applied: rig file: capture.pattern_delay_s "
                                 f"{result['suggested']['capture.pattern_delay_s']}, capture.camera.exposure_us "
                                 f"{result['suggested']['capture.camera.exposure_us']}")
    # Calibrate: 12 poses kept (one retaken), corners drawn live, a rig file within calibrate's tolerances.
    cal = result["calibration"]
    assert cal["final"]["state"] == "done", cal["final"]
    assert cal["corners"] == 54 and cal["moved"] and cal["dragged"] and cal["retaken"]
    assert len(cal["final"]["poses"]) == 12 and all(p["kept"] for p in cal["final"]["poses"])
    assert all(h.startswith("next: the board near the") for h in cal["hints"])
    assert outside_tolerances(compare_rigs(rig, default_rig())) == []
    assert rig.capture["camera"]["exposure_us"] == result["suggested"]["capture.camera.exposure_us"]   # kept
    # Scan: the first view drawn while views were still to take; an ordinary, finished session.
    assert 1 <= result["taken"] < 6 and result["shown"] > 5000
    assert result["count"] == 6 and (sessions / "first" / "mesh.ply").is_file() and result["scan_mesh"] > 1000
    assert "rangekit" in result["report_title"].lower()
    # Registration: one pair, its residual shown, the files saved under the name.
    assert len(result["pairs"]) == 1 and result["pairs"][0]["accepted"] and result["pairs"][0]["rmse_mm"] < 0.5
    assert (sessions / "two-views" / "poses.json").is_file() and (sessions / "two-views" / "merged.ply").is_file()
