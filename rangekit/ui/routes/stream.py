"""``WS /ws/live``: the camera stream, each frame a text message (its figures, JSON) then a binary one (JPEG);
``{"waiting": why}`` while there is no frame."""

from __future__ import annotations

import json

from rangekit.ui.routes.common import Ui

__all__ = ["MAX_STREAMS", "routes"]

#: The live streams open at once (each holds a thread of the pool while it waits for a frame).
MAX_STREAMS = 8


def routes(ui: Ui) -> list:
    from starlette.concurrency import run_in_threadpool
    from starlette.routing import WebSocketRoute
    from starlette.websockets import WebSocketDisconnect

    streams = {"open": 0}

    async def live(ws):
        if streams["open"] >= MAX_STREAMS:
            await ws.close(code=1013, reason=f"at most {MAX_STREAMS} live streams at once")
            return
        await ws.accept()
        streams["open"] += 1
        ui.stream.watch()
        seq = 0
        try:
            while True:
                frame = await run_in_threadpool(ui.stream.next_after, seq, 1.0)
                if frame is None:
                    await ws.send_text(json.dumps({"waiting": ui.holder.busy or ui.stream.error or "no frame yet"}))
                    continue
                seq = frame.seq
                await ws.send_text(json.dumps(frame.figures()))
                await ws.send_bytes(frame.jpeg)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            streams["open"] -= 1
            ui.stream.unwatch()

    return [WebSocketRoute("/ws/live", live)]
