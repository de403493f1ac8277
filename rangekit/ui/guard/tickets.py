"""Short-lived, single-use tickets for what a page loads without its script adding a header: the live stream's
WebSocket, a session's report in its iframe.

The page asks for one with a header-authenticated ``POST /api/ticket`` ``{"path"}``; the ticket then opens that one
path once, within :data:`TICKET_LIFETIME_S`. A ticket seen by anyone else afterwards (a log, a Referer, a leaked
URL) opens nothing: it is spent, or it has expired, and it never named another path.
"""

from __future__ import annotations

import hmac
import secrets
import threading
import time

__all__ = ["MAX_TICKETS", "TICKET_LIFETIME_S", "Tickets"]

#: Seconds a ticket stays valid unused.
TICKET_LIFETIME_S = 30.0
#: The most unused tickets kept (the oldest dropped beyond): a page asks for a few at a time.
MAX_TICKETS = 64


class Tickets:
    """The unused tickets: ``issue(path)`` makes one for ``path``, ``redeem(path, ticket)`` spends it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._open: dict[str, tuple[str, float]] = {}     # ticket -> (path, deadline)

    def issue(self, path: str) -> str:
        ticket = secrets.token_urlsafe(24)
        with self._lock:
            self._drop_expired()
            while len(self._open) >= MAX_TICKETS:
                self._open.pop(next(iter(self._open)))
            self._open[ticket] = (path, time.monotonic() + TICKET_LIFETIME_S)
        return ticket

    def redeem(self, path: str, ticket: str | None) -> bool:
        """Whether ``ticket`` opens ``path`` now; a ticket that does is spent."""
        if not ticket:
            return False
        with self._lock:
            self._drop_expired()
            for known, (where, _) in self._open.items():
                if hmac.compare_digest(known.encode(), ticket.encode()):
                    if where != path:
                        return False
                    del self._open[known]
                    return True
        return False

    def _drop_expired(self) -> None:
        now = time.monotonic()
        for ticket in [t for t, (_, deadline) in self._open.items() if deadline < now]:
            del self._open[ticket]
