"""``rangekit ui`` started for real, as a child process on 127.0.0.1 (a free port), for the tests of tests/ui."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from urllib.parse import urlsplit


@dataclass
class Server:
    proc: subprocess.Popen
    url: str            # as printed, with the token
    token: str
    base: str           # http://127.0.0.1:PORT
    err: list = field(default_factory=list)        # the server's stderr lines so far (read as it writes them)
    drains: list = field(default_factory=list)     # the threads reading its stdout and stderr

    def request(self, path: str, *, data=None, token: str | None = "header", headers: dict | None = None,
                method: str | None = None, raw: bytes | None = None):
        """(status, body bytes, headers) of a request to ``path``, as the app's page makes it: the token in its
        ``X-Rangekit-Token`` header and, for a POST, the app's own ``Origin`` and a JSON body (``data``; ``raw``:
        these bytes instead). ``token``: "header", "query" (``?token=``), None (no token) or another string (a
        wrong one, in the header); ``headers`` override any of these."""
        headers = dict(headers or {})
        url = self.base + path
        if token == "query":
            url += ("&" if "?" in url else "?") + f"token={self.token}"
        elif token is not None:
            headers.setdefault("X-Rangekit-Token", self.token if token == "header" else token)
        body = raw if raw is not None else (None if data is None else json.dumps(data).encode())
        if body is not None:
            headers.setdefault("Content-Type", "application/json")
            headers.setdefault("Origin", self.base)
        req = urllib.request.Request(url, data=body, headers={k: v for k, v in headers.items() if v is not None},
                                     method=method or ("POST" if body is not None else "GET"))
        try:
            with urllib.request.urlopen(req, timeout=30) as r:
                return r.status, r.read(), dict(r.headers)
        except urllib.error.HTTPError as e:
            return e.code, e.read(), dict(e.headers)

    def ticket(self, path: str) -> str:
        """A single-use ticket for ``path`` (the WebSocket, a session's file), as the page asks for one."""
        status, body, _ = self.request("/api/ticket", data={"path": path})
        assert status == 200, body
        return json.loads(body)["ticket"]

    def stop(self) -> str:
        """Stop the server (SIGINT, as Ctrl-C); its stderr."""
        if self.proc.poll() is None:
            self.proc.send_signal(2)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for t in self.drains:
            t.join(timeout=10)
        return "".join(self.err)


def _drain(stream, into: list | None) -> threading.Thread:
    """A thread reading ``stream`` to its end, its lines kept in ``into`` (None: dropped). A pipe nobody reads
    fills at 64 kB, and the server then blocks on its next write: its log lines, a traceback of a closed socket."""
    def read() -> None:
        for line in stream:
            if into is not None:
                into.append(line)

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t


def start_ui(sessions, *args: str, timeout: float = 60.0, port: int = 0) -> Server:
    """``rangekit ui --port PORT --sessions SESSIONS ARGS`` in a child process (port 0: a free one); returns once
    it printed its URL."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "rangekit", "ui", "--port", str(port), "--sessions", str(sessions), *args],
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
            server = Server(proc, url, token, f"{parts.scheme}://{parts.netloc}")
            server.drains = [_drain(proc.stdout, None), _drain(proc.stderr, server.err)]
            return server
    proc.kill()
    raise RuntimeError(f"rangekit ui printed no URL: {proc.stderr.read()}")


def serving(tmp_path_factory):
    """A module's ``rangekit ui`` on a fresh sessions folder (as ``.sessions``), stopped after the module's tests,
    its log then in ``.log``: make it the module's fixture with
    ``server = pytest.fixture(scope="module", name="server")(serving)``."""
    sessions = tmp_path_factory.mktemp("sessions")
    s = start_ui(sessions)
    s.sessions = sessions
    yield s
    s.log = s.stop()
