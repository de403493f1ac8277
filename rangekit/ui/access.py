"""Who may talk to ``rangekit ui``: the one-time token in a header, the app's own origin, the host it was started on.

Every port of 127.0.0.1 is the same *site* and sees the same cookies: a page served by any other local program
could send the browser's cookies along with a form post, and would receive any cookie the app set. So the app
sets no cookie at all, and the token never travels by itself:

- **The page** (``GET /``) and its scripts and styles (``/static/``) are package data with nothing secret: they
  are served without the token (a reloaded tab must load). The URL ``rangekit ui`` prints carries the token as
  ``?token=``; the page's script reads it once, keeps it in ``sessionStorage`` (this tab and this origin only:
  another port is another origin) and replaces the address (``history.replaceState``) so it leaves the address
  bar and the history. A ``?token=`` that is wrong is refused at once.
- **Every API request** carries the token in the ``X-Rangekit-Token`` header, which only the page's own script
  adds (OctoPrint's API keys): a form, an ``<img>``, a no-cors fetch cannot set it, and a cross-origin fetch that
  sets it needs a CORS preflight the server never grants.
- **Every request that changes state** (any method but GET and HEAD) must also come from the app's own page, its
  ``Origin`` exactly the server's ``http://host:port``, with ``Content-Type: application/json`` (a form can only
  send text/plain, urlencoded or multipart), and a body of at most :data:`rangekit.ui.guard.body.MAX_BODY_BYTES`
  by its Content-Length (413 before a byte is read).
- **What the page loads without its script adding a header** (the live stream's WebSocket, a session's report in
  its iframe) opens with a short-lived, single-use ticket bound to that one path
  (:mod:`rangekit.ui.guard.tickets`), asked for by a header-authenticated ``POST /api/ticket``; images are fetched
  with the header and shown as blob URLs. The WebSocket's ``Origin`` must still be the app's own.
- **Every request** must name the server in its ``Host`` (or ``localhost`` for a loopback one): a DNS-rebinding
  page is refused.

Nothing here is a cookie, so a cookie leaked to another port grants nothing, and a second ``rangekit ui`` in the
same browser leaves the first alone. A refusal is 403 (413 for a body too large) with ``{"error": one line}``; a
refused WebSocket is closed before it is accepted (code 1008). Every response carries the headers of
:mod:`rangekit.ui.guard.headers` (nosniff, framing, CSP).
"""

from __future__ import annotations

import hmac
import json
import secrets
from urllib.parse import parse_qs

from rangekit.ui.guard.body import MAX_BODY_BYTES, too_large
from rangekit.ui.guard.headers import security_headers
from rangekit.ui.guard.tickets import Tickets

__all__ = ["HEADER", "Gate", "new_token"]

#: The header the page's script adds to every request.
HEADER = "x-rangekit-token"
#: What refuses the token: the page recognises it (the server restarted: its token is another).
TOKEN_REFUSED = "token missing or wrong: open the URL rangekit ui printed (it holds the token)"
_SAFE = ("GET", "HEAD")


def new_token() -> str:
    """A fresh random token (32 bytes, URL-safe), made at every start of the server."""
    return secrets.token_urlsafe(32)


def _same(given: str | None, token: str) -> bool:
    return given is not None and hmac.compare_digest(given.encode(), token.encode())


def _media_type(value: str) -> str:
    return value.split(";", 1)[0].strip().lower()


class Gate:
    """An ASGI middleware (Starlette's ``Middleware(Gate, ...)``, :func:`rangekit.ui.server.make_app`) refusing what lacks the token, a change from another origin, or a foreign Host; it adds
    the security headers to every response.

    ``hosts``: the ``host:port`` values the Host header may name; ``origins``: the ``Origin`` values a change or a
    WebSocket may come from; ``page_csp``: the app page's Content-Security-Policy (``{host}`` filled in)."""

    def __init__(self, app, token: str, hosts: set[str], origins: set[str], page_csp: str,
                 tickets: Tickets | None = None) -> None:
        self.app, self.token, self.hosts, self.origins, self.page_csp = app, token, hosts, origins, page_csp
        self.tickets = tickets if tickets is not None else Tickets()

    def _refusal(self, scope, headers: dict) -> tuple[int, str] | None:
        if headers.get("host", "") not in self.hosts:
            return 403, f"host {headers.get('host', '')!r} refused: open the URL rangekit ui printed"
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        path, method = scope["path"], scope.get("method", "GET")
        if scope["type"] == "websocket" or method not in _SAFE:
            if headers.get("origin", "") not in self.origins:
                return 403, f"origin {headers.get('origin', '')!r} refused: only the app's own page may do this"
        if scope["type"] == "websocket":
            ticket = query.get("ticket", [None])[0]
            return None if self.tickets.redeem(path, ticket) else (403, "ticket missing, spent or expired: "
                                                                       "ask the page to connect again")
        if method not in _SAFE:
            if _media_type(headers.get("content-type", "")) != "application/json":
                return 403, f"content type {headers.get('content-type', '')!r} refused: expected application/json"
            length = headers.get("content-length", "0")
            if not length.isdigit() or int(length) > MAX_BODY_BYTES:
                return 413, too_large(int(length) if length.isdigit() else None)
        elif path == "/":
            given = query.get("token", [None])[0]
            return None if given is None or _same(given, self.token) else (403, TOKEN_REFUSED)
        elif path.startswith("/static/"):
            return None
        elif self.tickets.redeem(path, query.get("ticket", [None])[0]):
            return None
        return None if _same(headers.get(HEADER), self.token) else (403, TOKEN_REFUSED)

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        refused = self._refusal(scope, headers)
        if scope["type"] == "websocket":
            if refused is None:
                await self.app(scope, receive, send)
                return
            await receive()     # the websocket.connect message
            await send({"type": "websocket.close", "code": 1008, "reason": refused[1][:120]})
            return
        extra = security_headers(scope["path"], headers.get("host", ""), self.page_csp)

        async def send_guarded(message) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in extra}
                kept = [(k, v) for k, v in message.get("headers", []) if k.lower() not in names]
                message = {**message, "headers": kept + extra}
            await send(message)

        if refused is None:
            await self.app(scope, receive, send_guarded)
            return
        body = (json.dumps({"error": refused[1]}) + "\n").encode()
        await send_guarded({"type": "http.response.start", "status": refused[0],
                            "headers": [(b"content-type", b"application/json"),
                                        (b"content-length", str(len(body)).encode()),
                                        (b"cache-control", b"no-store")]})
        await send_guarded({"type": "http.response.body", "body": body})
