"""The page and what opens without a header: ``GET /`` (``static/index.html``; its script keeps the ``?token=`` it
was opened with), ``GET /static/...`` (its scripts and styles, package data, no network), ``POST /api/ticket``
``{"path"}`` (a single-use ticket opening ``path`` once: a WebSocket, a session's file in the report's iframe)."""

from __future__ import annotations

from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.guard.fields import text
from rangekit.ui.routes.common import Ui, action

__all__ = ["SOCKETS", "STATIC", "routes"]

STATIC = Path(__file__).resolve().parents[1] / "static"
#: The WebSockets a page opens (each with a ticket).
SOCKETS = ("/ws/live", "/ws/events", "/ws/jobs")


def routes(ui: Ui) -> list:
    from starlette.responses import FileResponse
    from starlette.routing import Mount, Route
    from starlette.staticfiles import StaticFiles

    async def index(request):
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    def ticket(request, f):
        path = f["path"]
        if path not in SOCKETS and not (path.startswith("/api/sessions/") and "/files/" in path):
            raise RangekitError(f"path: {path[:80]!r}: no ticket for it; expected {' or '.join(SOCKETS)} or a "
                                "session's file")
        return {"ticket": ui.tickets.issue(path)}

    return [Route("/", index), Route("/api/ticket", action("ticket", {"path": text()}, ticket), methods=["POST"]),
            Mount("/static", StaticFiles(directory=STATIC), name="static")]
