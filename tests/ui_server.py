"""``rangekit ui`` started for real, as a child process on 127.0.0.1 (a free port), for the tests of tests/ui."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from urllib.parse import urlsplit


@dataclass
class Server:
    proc: subprocess.Popen
    url: str            # as printed, with the token
    token: str
    base: str           # http://127.0.0.1:PORT

    def request(self, path: str, *, data=None, token: str | None = "cookie", headers: dict | None = None):
        """(status, body bytes, headers) of a request to ``path``; ``token``: "cookie" (the token as the page's
        cookie), "query", None (no token) or another string (a wrong one, as a cookie)."""
        headers = dict(headers or {})
        url = self.base + path
        if token == "query":
            url += ("&" if "?" in url else "?") + f"token={self.token}"
        elif token == "cookie":
            headers.setdefault("Cookie", f"rangekit_token={self.token}")
        elif token is not None:
            headers.setdefault("Cookie", f"rangekit_token={token}")
        body = None if data is None else json.dumps(data).encode()
        if body is not None:
            headers.setdefault("Content-Type", "application/json")
        req = urllib.request.Request(url, data=body, headers=headers, method="POST" if body is not None else "GET")
        try:
            with urllib.request.urlopen(req, timeout=30) as r:
                return r.status, r.read(), dict(r.headers)
        except urllib.error.HTTPError as e:
            return e.code, e.read(), dict(e.headers)

    def stop(self) -> str:
        """Stop the server (SIGINT, as Ctrl-C); its stderr."""
        if self.proc.poll() is None:
            self.proc.send_signal(2)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.stderr.read() if self.proc.stderr else ""


def start_ui(sessions, *args: str, timeout: float = 60.0) -> Server:
    """``rangekit ui --port 0 --sessions SESSIONS ARGS`` in a child process; returns once it printed its URL."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "rangekit", "ui", "--port", "0", "--sessions", str(sessions), *args],
                            stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        if line.startswith("http://"):
            url = line.strip()
            parts = urlsplit(url)
            token = parts.query.removeprefix("token=")
            return Server(proc, url, token, f"{parts.scheme}://{parts.netloc}")
    proc.kill()
    raise RuntimeError(f"rangekit ui printed no URL: {proc.stderr.read()}")
