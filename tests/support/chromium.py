"""Open a self-contained HTML page in headless Chromium and report on its images.

Drives Debian's ``chromium`` through ``chromedriver``'s W3C WebDriver HTTP API
using only the standard library (urllib + json + subprocess): no selenium, no
playwright, no browser downloads.  Install the browser with
``apt-get install chromium chromium-driver`` (``make test`` does this as root).

    python tests/support/chromium.py PAGE.html --screenshot out.png [--width 1280] [--height 900]
"""

from __future__ import annotations

import argparse
import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

__all__ = ["chromium_paths", "open_page", "Page"]

_BROWSERS = ("chromium", "chromium-browser")
_DRIVERS = ("chromedriver",)


def _find(names: tuple[str, ...]) -> str | None:
    for name in names:
        path = shutil.which(name)
        if path:
            return path
        candidate = Path("/usr/bin") / name
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return str(candidate)
    return None


def chromium_paths() -> tuple[str, str] | None:
    """(browser, driver) executables, or None when either is missing."""
    browser, driver = _find(_BROWSERS), _find(_DRIVERS)
    if browser and driver:
        return browser, driver
    return None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class WebDriverError(RuntimeError):
    pass


class _Client:
    def __init__(self, base: str):
        self.base = base
        # Talk to localhost directly, whatever http_proxy says.
        self._opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))

    def call(self, method: str, path: str, body: dict | None = None, timeout: float = 60.0):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        if data is not None:
            req.add_header("Content-Type", "application/json; charset=utf-8")
        try:
            with self._opener.open(req, timeout=timeout) as resp:
                payload = json.loads(resp.read() or b"{}")
        except urllib.error.HTTPError as exc:
            try:
                payload = json.loads(exc.read() or b"{}")
            except ValueError:
                payload = {}
            value = payload.get("value") if isinstance(payload, dict) else None
            if isinstance(value, dict):
                first_line = (str(value.get("message") or "").splitlines() or [""])[0]
                msg = f"{value.get('error')}: {first_line}"
            else:
                msg = str(exc)
            raise WebDriverError(f"{method} {path} -> HTTP {exc.code}: {msg}") from None
        return payload.get("value") if isinstance(payload, dict) else payload


def _wait_ready(client: _Client, proc: subprocess.Popen, deadline: float) -> None:
    while True:
        if proc.poll() is not None:
            raise WebDriverError(f"chromedriver exited early with code {proc.returncode}")
        try:
            if client.call("GET", "/status", timeout=2).get("ready"):
                return
        except (OSError, WebDriverError, ValueError):
            pass
        if time.monotonic() > deadline:
            raise WebDriverError("chromedriver did not become ready")
        time.sleep(0.05)


def _stop(proc: subprocess.Popen) -> None:
    """Terminate chromedriver and everything it started (its own process group)."""
    if proc.poll() is not None:
        return
    for sig, wait in ((signal.SIGTERM, 5), (signal.SIGKILL, 5)):
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            proc.send_signal(sig)
        try:
            proc.wait(timeout=wait)
            break
        except subprocess.TimeoutExpired:
            continue
    # Chromium children may outlive the driver briefly; clean up the group.
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


_ALL_IMAGES_COMPLETE = "return Array.from(document.images).every(function (i) { return i.complete; });"

_COLLECT = """
return {
  images: Array.from(document.images).map(function (img, i) {
    var src = img.currentSrc || img.src || '';
    return {index: i, src_prefix: src.slice(0, 40), complete: img.complete,
            naturalWidth: img.naturalWidth, naturalHeight: img.naturalHeight,
            alt: img.getAttribute('alt') || ''};
  }),
  svg_count: document.querySelectorAll('svg').length,
  title: document.title,
  scroll_height: document.body ? document.body.scrollHeight : 0,
  viewport: [window.innerWidth, window.innerHeight]
};
"""


class Page:
    """The open page, for an ``interact`` callback of :func:`open_page`: run scripts, find elements, drag."""

    def __init__(self, client: _Client, sid: str):
        self._client, self._sid = client, sid

    def execute(self, script: str, *args):
        """Run ``script`` (a function body; ``arguments[i]`` are ``args``) in the page; returns its value."""
        return self._client.call("POST", f"/session/{self._sid}/execute/sync", {"script": script, "args": list(args)})

    def element(self, css: str) -> dict:
        """The WebDriver reference of the first element matching the CSS selector ``css``."""
        return self._client.call("POST", f"/session/{self._sid}/element", {"using": "css selector", "value": css})

    def until(self, script: str, timeout: float = 60.0, describe: str | None = None):
        """Run ``script`` every 0.1 s until it returns something true; that value (AssertionError after
        ``timeout`` seconds, naming the script and, with ``describe`` (a script too), what the page then showed)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = self.execute(script)
            if value:
                return value
            time.sleep(0.1)
        shown = f"; the page then showed: {self.execute(describe)!r}" if describe else ""
        raise AssertionError(f"the page never satisfied: {script}{shown}")

    def goto(self, url: str) -> None:
        """Navigate this tab to ``url`` (an http://127.x.x.x page: another local server, the app again)."""
        self._client.call("POST", f"/session/{self._sid}/url", {"url": url})

    def frame(self, css: str | None) -> None:
        """Run the next scripts inside the iframe matching ``css`` (even one of another origin, as a sandboxed
        one is); None: back to the top page."""
        target = None if css is None else self.element(css)
        self._client.call("POST", f"/session/{self._sid}/frame", {"id": target})

    def cdp(self, cmd: str, params: dict | None = None):
        """Send the DevTools command ``cmd`` to the page (``Network.setBlockedURLs``, ...); its result."""
        return self._client.call("POST", f"/session/{self._sid}/goog/cdp/execute", {"cmd": cmd, "params": params or {}})

    def screenshot(self, out: str | Path) -> None:
        """The viewport as it is now, a PNG at ``out`` (a page's state mid-interaction, for the docs)."""
        _screenshot(self._client, self._sid, Path(out), 0, 0, full_page=False)

    def drag(self, element: dict, dx: int, dy: int, steps: int = 10) -> None:
        """Press the mouse at the centre of ``element``, move by (dx, dy) pixels in ``steps``, release."""
        moves = [{"type": "pointerMove", "duration": 20, "origin": "pointer", "x": round(dx / steps), "y": round(dy / steps)}
                 for _ in range(steps)]
        self._client.call("POST", f"/session/{self._sid}/actions", {"actions": [{
            "type": "pointer", "id": "mouse", "parameters": {"pointerType": "mouse"},
            "actions": [{"type": "pointerMove", "duration": 0, "origin": element, "x": 0, "y": 0},
                        {"type": "pointerDown", "button": 0}, *moves, {"type": "pointerUp", "button": 0}]}]})
        self._client.call("DELETE", f"/session/{self._sid}/actions")


def _poll(client: _Client, sid: str, script: str, deadline: float) -> bool:
    while True:
        if client.call("POST", f"/session/{sid}/execute/sync", {"script": script, "args": []}):
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)


def _screenshot(client: _Client, sid: str, out: Path, width: int, height: int, full_page: bool) -> None:
    png_b64 = None
    if full_page:
        try:
            result = client.call("POST", f"/session/{sid}/goog/cdp/execute", {
                "cmd": "Page.captureScreenshot",
                "params": {"captureBeyondViewport": True, "format": "png",
                           "clip": {"x": 0, "y": 0, "width": width, "height": height, "scale": 1}},
            })
            png_b64 = result["data"]
        except (WebDriverError, KeyError, TypeError):
            png_b64 = None
    if png_b64 is None:
        png_b64 = client.call("GET", f"/session/{sid}/screenshot")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(base64.b64decode(png_b64))


def open_page(html_path, *, width: int = 1280, height: int = 900,
              screenshot: str | Path | None = None, full_page: bool = True,
              timeout_s: float = 60, interact=None) -> dict:
    """Load ``html_path`` (a file, or an ``http://127.x.x.x`` URL) in headless Chromium; report on its images,
    optionally screenshot it.

    Returns ``{"images": [{"index", "src_prefix", "complete", "naturalWidth",
    "naturalHeight", "alt"}, ...], "svg_count", "title", "scroll_height",
    "screenshot", "interaction"}``; an image that failed to load has ``naturalWidth == 0``. ``interact``:
    called with a :class:`Page` once the page has loaded (before the screenshot); its return value is
    "interaction".
    """
    paths = chromium_paths()
    if paths is None:
        raise FileNotFoundError("chromium/chromedriver not found: apt-get install chromium chromium-driver")
    browser, driver = paths
    # a page file, or a URL on this machine (a local server: tests/ui)
    url = str(html_path) if str(html_path).startswith("http://127.") else Path(html_path).resolve().as_uri()
    deadline = time.monotonic() + timeout_s

    profile = tempfile.mkdtemp(prefix="rangekit-chromium-")
    port = _free_port()
    proc = subprocess.Popen(
        [driver, f"--port={port}", "--allowed-ips=127.0.0.1"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,  # own process group, so chromium children go with it
    )
    client = _Client(f"http://127.0.0.1:{port}")
    sid = None
    try:
        _wait_ready(client, proc, min(deadline, time.monotonic() + 20))
        caps = {"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {"binary": browser, "args": [
                "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--disable-quic", "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                f"--user-data-dir={profile}", f"--window-size={width},{height}",
            ]},
        }}}
        sid = client.call("POST", "/session", caps, timeout=timeout_s)["sessionId"]
        remaining = max(1.0, deadline - time.monotonic())
        client.call("POST", f"/session/{sid}/timeouts",
                    {"pageLoad": int(remaining * 1000), "script": int(remaining * 1000)})
        try:  # make the viewport exactly width x height at scale 1 (--window-size includes browser UI)
            client.call("POST", f"/session/{sid}/goog/cdp/execute", {
                "cmd": "Emulation.setDeviceMetricsOverride",
                "params": {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}})
        except WebDriverError:
            pass
        client.call("POST", f"/session/{sid}/url", {"url": url}, timeout=remaining + 5)
        _poll(client, sid, "return document.readyState === 'complete';", deadline)
        _poll(client, sid, _ALL_IMAGES_COMPLETE, deadline)
        info = client.call("POST", f"/session/{sid}/execute/sync", {"script": _COLLECT, "args": []})
        interaction = interact(Page(client, sid)) if interact is not None else None
        shot = None
        if screenshot is not None:
            shot = Path(screenshot)
            page_h = max(height, int(info["scroll_height"] or 0))
            _screenshot(client, sid, shot, width, page_h, full_page)
        return {"images": info["images"], "svg_count": info["svg_count"], "title": info["title"],
                "scroll_height": info["scroll_height"], "screenshot": str(shot) if shot else None,
                "interaction": interaction}
    finally:
        if sid is not None:
            try:
                client.call("DELETE", f"/session/{sid}", timeout=10)
            except (OSError, WebDriverError, ValueError):
                pass
        _stop(proc)
        shutil.rmtree(profile, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("page", help="self-contained HTML file")
    ap.add_argument("--screenshot", help="write a PNG screenshot here")
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--viewport-only", action="store_true", help="screenshot the viewport, not the full page")
    ap.add_argument("--timeout", type=float, default=60)
    args = ap.parse_args(argv)
    if chromium_paths() is None:
        print("chromium/chromedriver not found: apt-get install chromium chromium-driver", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    res = open_page(args.page, width=args.width, height=args.height, screenshot=args.screenshot,
                    full_page=not args.viewport_only, timeout_s=args.timeout)
    broken = [im for im in res["images"] if not (im["complete"] and im["naturalWidth"] > 0)]
    print(f"title: {res['title']!r}  images: {len(res['images'])}  broken: {len(broken)}  "
          f"inline svg: {res['svg_count']}  scroll height: {res['scroll_height']}px  "
          f"({time.monotonic() - t0:.1f} s)")
    for im in res["images"]:
        ok = "ok    " if im["complete"] and im["naturalWidth"] > 0 else "BROKEN"
        print(f"  [{im['index']}] {ok} {im['naturalWidth']}x{im['naturalHeight']}  "
              f"alt={im['alt']!r}  src={im['src_prefix']}")
    if res["screenshot"]:
        print(f"screenshot: {res['screenshot']}")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
