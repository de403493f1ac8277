"""The requests a page of ``rangekit ui`` makes while it sits open (issue 49: no polling timers): each page shown
SECONDS in turn (Live, Check, Calibrate, Registration, Sessions), nothing running, every ``fetch`` of the page's
scripts recorded. Before issue 49 the pages polled ``/api/status`` every 2 s and the shown page's job every 0.6 to
2 s; now a page asks only when it is shown or a person acts, and the jobs' state comes over ``/ws/jobs``.

    .venv/bin/python benchmarks/ui/bench_page_requests.py [SECONDS]     # default 30; headless Chromium

``rangekit ui --port 0`` on 127.0.0.1 started for real from this checkout (``PYTHONPATH`` names another checkout to
count its pages instead). Prints one line a page: the requests made and the paths asked.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from support.chromium import open_page  # noqa: E402
from support.ui_server import start_ui  # noqa: E402

PAGES = ("live", "check", "calibrate", "register", "sessions")
#: Every fetch of the page's scripts recorded (api.js calls the window's fetch).
RECORD = ("window.asked = []; const fetched = window.fetch;"
          "window.fetch = (url, init) => { window.asked.push(String(url)); return fetched(url, init); };")


def main(seconds: float = 30.0) -> None:
    server = start_ui(tempfile.mkdtemp(prefix="rangekit-requests-"))
    try:
        def count(page):
            page.until("return document.getElementById('rig-source').textContent.length > 0;")
            page.execute(RECORD)
            out = {}
            for name in PAGES:
                page.execute(f"window.asked = []; location.hash = '#{name}';")
                time.sleep(seconds)
                out[name] = page.execute("return window.asked;")
            return out

        asked = open_page(server.url, interact=count, timeout_s=60 + len(PAGES) * seconds)["interaction"]
    finally:
        server.stop()
    for name in PAGES:
        print(f"{name:10s} {len(asked[name]):4d} requests in {seconds:g} s: {', '.join(sorted(set(asked[name])))}")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 30.0)
