"""``WS /ws/jobs``: the state of every job but the scan (check, calibrate, recorded, register) and of the rig, sent
when it changes (a ticket opens it, as ``/ws/events``; :mod:`rangekit.ui.access`). The scan has its own events
(``/ws/events``).

Messages, each one JSON text:

- ``{"job": NAME, "snapshot": {...}}``: job NAME's state, what ``GET /api/NAME`` answers (``NAME``: check,
  calibrate, recorded, register; ``GET /api/calibrate-recorded`` for recorded);
- ``{"rig": {...}}``: the rig's status, what ``GET /api/status`` answers.

A page that connects is sent every job's state and the rig's first, then each topic again whenever it changes
(:class:`rangekit.ui.jobs.notifier.Notifier`: no timer, no polling; changes faster than the page reads fold into
one message). A page that reconnects is sent every state again: it misses nothing.
"""

from __future__ import annotations

import asyncio

from rangekit.errors import RangekitError
from rangekit.ui.jobs.notifier import Topic
from rangekit.ui.routes.common import Ui

__all__ = ["JOBS", "MAX_FOLLOWERS", "routes"]

#: The jobs sent, by topic: the :class:`rangekit.ui.routes.common.Ui` field holding each.
JOBS = {Topic.CHECK: "check", Topic.CALIBRATE: "calibration", Topic.RECORDED: "recorded",
        Topic.REGISTER: "registration"}
#: The job sockets open at once.
MAX_FOLLOWERS = 16


def routes(ui: Ui) -> list:
    from starlette.concurrency import run_in_threadpool
    from starlette.routing import WebSocketRoute
    from starlette.websockets import WebSocketDisconnect

    from rangekit.ui.routes.rig import status_body

    open_ = {"n": 0}

    def message(topic: Topic) -> dict:
        if topic is Topic.RIG:
            return {"rig": status_body(ui)}
        return {"job": topic.value, "snapshot": getattr(ui, JOBS[topic]).snapshot()}

    async def send(ws, topics) -> None:
        for topic in topics:
            await ws.send_json(await run_in_threadpool(message, topic))

    async def jobs(ws):
        if open_["n"] >= MAX_FOLLOWERS:
            await ws.close(code=1013, reason=f"at most {MAX_FOLLOWERS} job sockets at once")
            return
        await ws.accept()
        open_["n"] += 1
        notifier = ui.notifier
        receiving = asyncio.ensure_future(ws.receive())
        waiting = None
        try:
            seen = notifier.version
            await send(ws, [*JOBS, Topic.RIG])
            while True:
                waiting = asyncio.ensure_future(notifier.wait(seen))
                done, _ = await asyncio.wait({receiving, waiting}, return_when=asyncio.FIRST_COMPLETED)
                if receiving in done:
                    if receiving.result()["type"] == "websocket.disconnect":
                        return
                    receiving = asyncio.ensure_future(ws.receive())    # the page says nothing we read
                    continue
                seen, changes = notifier.since(seen)
                await send(ws, [c.topic for c in changes])
        except (WebSocketDisconnect, RuntimeError, OSError, RangekitError):
            pass      # the page went away: it reconnects and is sent every state again
        finally:
            for task in (receiving, waiting):
                if task is not None and not task.done():
                    task.cancel()
            open_["n"] -= 1

    return [WebSocketRoute("/ws/jobs", jobs)]
