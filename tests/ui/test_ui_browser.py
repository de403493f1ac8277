"""The web app in a real browser (issue 37): headless Chromium (Debian's) opens the URL ``rangekit ui`` printed."""

from __future__ import annotations

import time

import pytest

from chromium import chromium_paths, open_page
from ui_server import start_ui

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


def _until(page, script: str, timeout: float = 60.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = page.execute(script)
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"the page never satisfied: {script}")


def test_the_live_page_streams_frames_and_marks_a_saturating_object(tmp_path):
    server = start_ui(tmp_path, "--object", "shiny")
    try:
        def look(page):
            _until(page, "return window.rangekitLive && window.rangekitLive.frames >= 3;")
            first = page.execute(_CANVAS)
            _until(page, f"return window.rangekitLive.frames >= {first['frames'] + 3};")
            second = page.execute(_CANVAS)
            page.execute("document.querySelector('[data-name=checker]').click();")
            _until(page, "return document.querySelector('[data-name=checker]').classList.contains('on');")
            # A non-numeric exposure: the rig file's one-line error next to its field, nothing else changed.
            page.execute("document.querySelector('[name=exposure_us]').value = 'abc';"
                         "document.querySelector('#controls button').click();")
            error = _until(page, "return document.querySelector('.field-error[data-for=exposure_us]').textContent;")
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


@pytest.mark.slow
def test_a_scan_started_in_the_page_shows_its_first_view_before_the_last_is_taken(tmp_path):
    """6 views in real time (about 80 s of acquisition), then the processing."""
    sessions = tmp_path / "sessions"
    sessions.mkdir()
    server = start_ui(sessions)
    try:
        def scan(page):
            page.execute("location.hash = '#scan';")
            page.execute("const f = document.getElementById('scan-form'); f.name.value = 'first';"
                         "f.views.value = '6'; document.getElementById('scan-start').click();")
            _until(page, "return window.rangekitScan3d && window.rangekitScan3d.count >= 1;", timeout=240)
            taken = page.execute("return fetch('/api/scan').then(r => r.json())"
                                 ".then(s => s.views.filter(v => v.done).length);")
            shown = page.execute("return window.rangekitScan3d.points;")
            _until(page, "return document.getElementById('scan-state').textContent.includes('ended (exit 0)');",
                   timeout=600)
            return taken, shown, page.execute("return window.rangekitScan3d.count;")

        out = open_page(server.url, width=1280, height=800, timeout_s=900, interact=scan,
                        screenshot=tmp_path / "scan.png")
        taken, shown, count = out["interaction"]
    finally:
        server.stop()
    assert 1 <= taken < 6 and shown > 5000          # the first view drawn while views were still to take
    assert count == 6 and (sessions / "first" / "mesh.ply").is_file()    # an ordinary, finished session
