"""Who may talk to ``rangekit ui``: a one-time token, the app's own origin, the host it was started on.

Every HTTP request and every WebSocket must carry the token printed at start, as ``?token=`` (the URL the
command prints) or the cookie the first page load sets (HttpOnly, SameSite=Strict: other sites' pages never
send it). A WebSocket must also come from the app's own page: its ``Origin`` must be the server's own
``http://host:port`` (a page of another site that guessed the token would still be refused; FabScanPi's
server accepts any origin). The ``Host`` header must name the address the server listens on (or
``localhost`` for a loopback one): a DNS-rebinding page is refused too.
"""

from __future__ import annotations

import hmac
import secrets
from http.cookies import SimpleCookie
from urllib.parse import parse_qs

__all__ = ["COOKIE", "Gate", "new_token"]

#: The cookie that carries the token after the first page load.
COOKIE = "rangekit_token"


def new_token() -> str:
    """A fresh random token (32 bytes, URL-safe), made at every start of the server."""
    return secrets.token_urlsafe(32)


class Gate:
    """An ASGI middleware refusing what lacks the token, a WebSocket from another origin, or a foreign Host.

    ``hosts``: the ``host:port`` values the Host header may name; ``origins``: the ``Origin`` values a
    WebSocket may come from. A refused HTTP request gets 403 and a one-line text; a refused WebSocket is
    closed before it is accepted (code 1008, policy violation)."""

    def __init__(self, app, token: str, hosts: set[str], origins: set[str]) -> None:
        self.app, self.token, self.hosts, self.origins = app, token, hosts, origins

    def _refusal(self, scope) -> str | None:
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        if headers.get("host", "") not in self.hosts:
            return f"host {headers.get('host', '')!r} refused: open the URL rangekit ui printed"
        if scope["type"] == "websocket" and headers.get("origin", "") not in self.origins:
            return f"origin {headers.get('origin', '')!r} refused: only the app's own page may connect"
        given = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token", [None])[0]
        if given is None:
            cookie = SimpleCookie()
            try:
                cookie.load(headers.get("cookie", ""))
            except Exception:   # noqa: BLE001 - a malformed cookie header is no token
                cookie = SimpleCookie()
            given = cookie[COOKIE].value if COOKIE in cookie else None
        if given is None or not hmac.compare_digest(given.encode(), self.token.encode()):
            return "token missing or wrong: open the URL rangekit ui printed (it holds the token)"
        return None

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        why = self._refusal(scope)
        if why is None:
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await receive()     # the websocket.connect message
            await send({"type": "websocket.close", "code": 1008, "reason": why[:120]})
            return
        body = (why + "\n").encode()
        await send({"type": "http.response.start", "status": 403,
                    "headers": [(b"content-type", b"text/plain; charset=utf-8"),
                                (b"content-length", str(len(body)).encode())]})
        await send({"type": "http.response.body", "body": body})
