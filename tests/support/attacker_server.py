"""Another local program's web server: a second HTTP server on 127.0.0.1 (its own port), serving an attacker's
pages to the same browser as ``rangekit ui``, and noting every request it receives (path, headers), so a test
sees what the browser sent it (a cookie meant for the app?) and what the attacker's page reported back."""

from __future__ import annotations

import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlsplit


class AttackerServer:
    """``pages``: path -> HTML; ``requests``: every request as ``{"path", "query", "headers"}``."""

    def __init__(self, pages: dict[str, str]) -> None:
        self.pages, self.requests = pages, []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):                       # noqa: N802 - http.server's name
                parts = urlsplit(self.path)
                outer.requests.append({"path": parts.path, "query": parse_qs(parts.query),
                                       "headers": {k.lower(): v for k, v in self.headers.items()}})
                body = outer.pages.get(parts.path, "").encode()
                self.send_response(200 if parts.path in outer.pages else 204)
                self.send_header("Content-Type", "text/html; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args):
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.base = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self) -> "AttackerServer":
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def reports(self, key: str) -> list[str]:
        """What the attacker's pages reported back (``/log?KEY=VALUE``), in order."""
        return [v for r in self.requests if r["path"] == "/log" for v in r["query"].get(key, [])]
