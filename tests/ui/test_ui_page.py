"""The page itself (issue 48): an unknown page name falls back to the first page, the camera controls show the
defaults in force, a scan folder's error stands by its field, a long session name wraps instead of pushing the
table (and its "open" buttons) off the page. Real headless Chromium on the real server."""

from __future__ import annotations

import pytest

from support.chromium import chromium_paths, open_page
from support.ui_server import start_ui

pytestmark = pytest.mark.skipif(chromium_paths() is None, reason="headless browser missing: apt-get install "
                                "chromium chromium-driver (`make test` installs them when run as root)")


def test_the_page_falls_back_shows_defaults_puts_errors_by_their_field_and_wraps_long_names(tmp_path):
    long_name = "n" * 250
    (tmp_path / long_name).mkdir()
    (tmp_path / long_name / "session.json").write_text("{not json")
    server = start_ui(tmp_path)
    try:
        def look(page):
            out = {}
            page.until("return document.getElementById('rig-source').textContent.length > 0;")
            out["controls"] = page.execute("return Object.fromEntries([...document.querySelectorAll('#controls input')]"
                                           ".map((i) => [i.name, i.value]));")
            page.execute("location.hash = '#nonsense';")
            out["shown"] = page.until("return [...document.querySelectorAll('main > section')]"
                                      ".filter((s) => !s.hidden).map((s) => s.id).join();")
            out["nav"] = page.execute("return document.querySelector('header nav a.on').getAttribute('href');")
            page.execute("location.hash = '#scan';")
            page.execute("const f = document.getElementById('scan-form'); f.name.value = '../elsewhere';"
                         "document.getElementById('scan-start').click();")
            out["field"] = page.until("return document.querySelector('#scan-form .field-error[data-for=name]')"
                                      ".textContent;")
            out["bottom"] = page.execute("return document.getElementById('scan-error').textContent;")
            page.execute("location.hash = '#sessions';")
            page.until(f"return !!document.querySelector('button[data-session=\"{long_name}\"]');")
            out["layout"] = page.execute(
                f"const b = document.querySelector('button[data-session=\"{long_name}\"]').getBoundingClientRect();"
                "return {page: document.documentElement.scrollWidth, view: innerWidth, "
                "table: document.getElementById('sessions-table').getBoundingClientRect().width, right: b.right};")
            return out

        out = open_page(server.url + "#nonsense", width=1280, height=900, timeout_s=120, interact=look)["interaction"]
    finally:
        server.stop()
    assert out["controls"] == {"exposure_us": "33333", "iso": "100", "white_balance_k": "5600", "focus": "130"}
    assert out["shown"] == "live" and out["nav"] == "#live"
    assert out["field"].startswith("name: '../elsewhere': begins with '.'") and out["bottom"] == ""
    layout = out["layout"]
    assert layout["page"] <= layout["view"] and layout["table"] <= layout["view"] and layout["right"] <= layout["view"]
