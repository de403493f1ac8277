"""``WS /ws/events?session=NAME&offset=N``: the scan job's events, as its session's ``events.jsonl`` grows (a ticket
opens it, as the live stream; :mod:`rangekit.ui.access`).

Messages, each one JSON text:

- ``{"session": NAME, "launch": K, "start": S, "offset": N}``: from now on the socket follows NAME's file from byte
  N (the job launched last, the app's K-th; ``start`` where its own events begin,
  :class:`rangekit.ui.jobs.scan.Followed`). Sent first, and
  again whenever the app launches another job. ``NAME`` null: no job since the app started. With ``"exited":
  {...}`` (a JobExited) when the job ended with no folder to hold its events (refused before it made it).
- ``{"event": {...}, "offset": END}``: one line of the file (:func:`rangekit.app.event_log.to_json`'s object), END
  the byte offset after it.

A page that reconnects sends the session and the offset it got to: the same session's file is replayed from there
(nothing twice, nothing missed); another session's from its beginning.
"""

from __future__ import annotations

import asyncio

from rangekit.errors import RangekitError
from rangekit.ui.routes.common import Ui

__all__ = ["MAX_FOLLOWERS", "WAIT_S", "routes"]

#: The event sockets open at once.
MAX_FOLLOWERS = 16
#: Seconds between two looks at the file's end when nothing new was there.
WAIT_S = 0.25


def _offset(text: str | None) -> int:
    return int(text) if text is not None and text.isdigit() and len(text) < 16 else 0


def routes(ui: Ui) -> list:
    from starlette.concurrency import run_in_threadpool
    from starlette.routing import WebSocketRoute
    from starlette.websockets import WebSocketDisconnect

    from rangekit.app.event_log import read_events

    open_ = {"n": 0}

    def new_lines(path, offset: int) -> list:
        return list(read_events(path, offset, typed=False)) if path is not None else []

    async def closed(ws) -> bool:
        """Whether the page went away (waiting at most :data:`WAIT_S` for it to say so)."""
        try:
            message = await asyncio.wait_for(ws.receive(), WAIT_S)
        except asyncio.TimeoutError:
            return False
        return message["type"] == "websocket.disconnect"

    async def events(ws):
        if open_["n"] >= MAX_FOLLOWERS:
            await ws.close(code=1013, reason=f"at most {MAX_FOLLOWERS} event sockets at once")
            return
        await ws.accept()
        open_["n"] += 1
        session, offset = ws.query_params.get("session"), _offset(ws.query_params.get("offset"))
        followed = None
        try:
            while True:
                job = ui.scans.followed
                if job != followed:
                    if job.name != session:
                        offset = 0
                    followed, session = job, job.name
                    await ws.send_json({"session": job.name, "launch": job.launch, "start": job.start,
                                        "offset": offset, **({"exited": job.exited} if job.exited else {})})
                lines = await run_in_threadpool(new_lines, job.path, offset)
                for obj, end in lines:
                    await ws.send_json({"event": obj, "offset": end})
                    offset = end
                if not lines and await closed(ws):
                    return
        except (WebSocketDisconnect, RuntimeError, OSError, RangekitError):
            pass      # the page went away, or a line that is no event (said in the file): the page reconnects
        finally:
            open_["n"] -= 1

    return [WebSocketRoute("/ws/events", events)]
