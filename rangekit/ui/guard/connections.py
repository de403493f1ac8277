"""The connections uvicorn holds for ``rangekit ui``, bounded: a local program opening a thousand connections and
never finishing a request must not exhaust the server's file descriptors nor fill its log.

- at most :data:`MAX_CONNECTIONS` at once: beyond it the oldest connection still waiting for its request's
  headers is closed (a page's quick request still gets in), or the new one when none waits;
- a request's headers must arrive within :data:`HEADER_TIMEOUT_S` (idle keep-alive: uvicorn's
  ``timeout_keep_alive``); at most :data:`MAX_HEADER_BYTES` of them (h11's limit);
- :data:`CONCURRENCY` connections and requests at once (uvicorn answers 503 beyond: a fallback);
- each kind of refusal is logged once, not once a request (:class:`OnceEach`).
"""

from __future__ import annotations

import logging

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["CONCURRENCY", "GuardedH11Protocol", "HEADER_TIMEOUT_S", "MAX_CONNECTIONS", "OnceEach", "server_options"]

MAX_CONNECTIONS = 200
CONCURRENCY = MAX_CONNECTIONS + 8     # uvicorn counts connections too: a fallback only
HEADER_TIMEOUT_S = 10.0
KEEP_ALIVE_S = 5
MAX_HEADER_BYTES = 16 * 1024

_log = logging.getLogger("uvicorn.error")


class OnceEach(logging.Filter):
    """Lets each kind of message (its first line) through once, saying that later ones are not logged."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        key = str(record.msg).splitlines()[0] if record.msg else ""
        if key in self.seen:
            return False
        self.seen.add(key)
        record.msg = f"{record.msg} (said once: the next ones are not logged)"
        return True


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with the connection cap and the header deadline."""

    def connection_made(self, transport) -> None:  # type: ignore[override]
        if len(self.connections) >= MAX_CONNECTIONS and not _evict_one(self.connections):
            _log.warning("rangekit ui: too many connections (%d): new ones closed", MAX_CONNECTIONS)
            self._refused = True
            transport.abort()
            return
        self._refused = False
        super().connection_made(transport)
        self._arm_header_deadline()

    def connection_lost(self, exc) -> None:
        if not getattr(self, "_refused", False):
            super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if not getattr(self, "_refused", False):
            super().data_received(data)

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._arm_header_deadline()

    @property
    def waiting_for_request(self) -> bool:
        """Whether the connection has no request under way (nothing yet, or only part of its headers)."""
        return self.conn.their_state is h11.IDLE and (self.cycle is None or self.cycle.response_complete)

    def _arm_header_deadline(self) -> None:
        self._waiting_since = self.loop.time()
        self.loop.call_later(HEADER_TIMEOUT_S, self._header_deadline, self._waiting_since)

    def _header_deadline(self, since: float) -> None:
        if (self in self.connections and self._waiting_since == since and self.waiting_for_request
                and not self.transport.is_closing()):
            _log.warning("rangekit ui: a request's headers did not arrive within %.0f s: connection closed",
                         HEADER_TIMEOUT_S)
            self.transport.close()


def _evict_one(connections) -> bool:
    """Close the connection that has waited longest for its request; whether there was one."""
    waiting = [c for c in connections if isinstance(c, GuardedH11Protocol) and c.waiting_for_request
               and not c.transport.is_closing()]
    if not waiting:
        return False
    oldest = min(waiting, key=lambda c: c._waiting_since)
    _log.warning("rangekit ui: too many connections (%d): the one waiting longest for its request closed",
                 MAX_CONNECTIONS)
    oldest.transport.abort()
    return True


def server_options() -> dict:
    """uvicorn.Config keywords of these bounds; the log filter installed on uvicorn's and asyncio's loggers."""
    for name in ("uvicorn.error", "asyncio"):
        logger = logging.getLogger(name)
        if not any(isinstance(f, OnceEach) for f in logger.filters):
            logger.addFilter(OnceEach())
    return {"http": GuardedH11Protocol, "limit_concurrency": CONCURRENCY, "timeout_keep_alive": KEEP_ALIVE_S,
            "h11_max_incomplete_event_size": MAX_HEADER_BYTES, "backlog": 128}
