"""The headless-Chromium harness (tests/support/chromium.py) reports broken images and takes screenshots."""

import base64
from pathlib import Path

import cv2
import numpy as np
import pytest

from support.chromium import chromium_paths, open_page

pytestmark = pytest.mark.skipif(
    chromium_paths() is None,
    reason="headless browser missing: apt-get install chromium chromium-driver "
           "(`make test` installs them when run as root)",
)

WIDTH, HEIGHT = 640, 480


def _png_data_uri(w, h, bgr):
    img = np.zeros((h, w, 3), np.uint8)
    img[:] = bgr
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """One tall page with two good images, one broken one and an inline SVG, opened once."""
    d = tmp_path_factory.mktemp("chromium")
    html = d / "page.html"
    broken = "data:image/png;base64," + base64.b64encode(b"\x89PNG\r\n\x1a\nnot really a png").decode()
    html.write_text(f"""<!doctype html>
<html><head><meta charset="utf-8"><title>harness test</title></head>
<body style="margin:0">
<img alt="red" style="display:block" src="{_png_data_uri(32, 24, (0, 0, 255))}">
<img alt="green" src="{_png_data_uri(16, 16, (0, 255, 0))}">
<img alt="broken" src="{broken}">
<svg width="50" height="50"><rect width="50" height="50" fill="blue"/></svg>
<div style="height:{2 * HEIGHT}px;background:#ddd"></div>
</body></html>""", encoding="utf-8")
    shot = d / "shot.png"
    return open_page(html, width=WIDTH, height=HEIGHT, screenshot=shot, timeout_s=30)


def test_reports_loaded_and_broken_images(page):
    imgs = {im["alt"]: im for im in page["images"]}
    assert [im["index"] for im in page["images"]] == [0, 1, 2]
    assert (imgs["red"]["naturalWidth"], imgs["red"]["naturalHeight"]) == (32, 24)
    assert (imgs["green"]["naturalWidth"], imgs["green"]["naturalHeight"]) == (16, 16)
    assert imgs["red"]["complete"] and imgs["green"]["complete"]
    assert imgs["broken"]["naturalWidth"] == 0  # what a report test keys on to fail
    assert all(im["src_prefix"].startswith("data:image/png;base64,") for im in page["images"])
    assert page["svg_count"] == 1
    assert page["title"] == "harness test"
    assert page["scroll_height"] >= 2 * HEIGHT


def test_full_page_screenshot(page):
    assert page["screenshot"] is not None
    shot = cv2.imread(page["screenshot"])
    assert shot is not None, "screenshot is not a readable PNG"
    assert Path(page["screenshot"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert shot.shape[1] == WIDTH
    assert shot.shape[0] >= HEIGHT
    assert shot.shape[0] >= page["scroll_height"] - 1  # full page, beyond the viewport
    # The 32x24 red image sits at the top-left corner.
    b, g, r = (int(v) for v in shot[5, 5])
    assert r > 200 and g < 60 and b < 60
    # Content below the first viewport was rendered too (the grey block), not left blank.
    assert all(abs(int(v) - 0xDD) <= 3 for v in shot[shot.shape[0] - 10, WIDTH // 2])
