"""``rangekit ui``: the web app's server (Starlette on uvicorn, WebSockets for the live stream and the events).

The routes live in :mod:`rangekit.ui.routes`, one module per resource: page (the page, its static files, tickets),
rig (status, pattern, turntable, camera controls), stream (``/ws/live``), check, calibrate (the wizard and the
recorded calibration), scan, events (``/ws/events``: the scan job's events), jobs (``/ws/jobs``: the other jobs'
and the rig's state, sent as it changes), sessions, register. The jobs live in :mod:`rangekit.ui.jobs`; each says
its changes on the app's one :class:`rangekit.ui.jobs.notifier.Notifier`, as the rig does. Every request passes :class:`rangekit.ui.access.Gate` first, as Starlette middleware (the
token in its header, the app's own origin for a change, the host; see there); every failure is answered by
:func:`rangekit.ui.routes.common.error_response` (``{"error", "field"}``). Every JSON field is type-checked first
(:mod:`rangekit.ui.guard.fields`), the body bounded (:mod:`rangekit.ui.guard.body`), and every device call and
file access runs off the event loop (Starlette's thread pool), so a turning turntable never stalls another page's
request.
"""

from __future__ import annotations

import contextlib
import socket
from dataclasses import dataclass
from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.access import Gate, new_token
from rangekit.ui.rig_holder import RigHolder

__all__ = ["UiServer", "bind", "make_app"]


@dataclass(frozen=True)
class UiServer:
    """What ``rangekit ui`` started: its URL (with the token) and the ASGI app."""

    url: str
    token: str
    app: object
    host: str
    port: int


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0: a free one), or a one-line error naming them."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        why = "is in use by another program" if exc.errno == 98 else f"cannot be opened ({exc.strerror})"
        raise RangekitError(f"--host {host} --port {port}: {why}; choose another with --port") from None
    sock.listen(128)
    return sock


def make_app(holder: RigHolder, token: str, host: str, port: int, sessions: Path, obj: str = "lumpy"):
    """The Starlette app for ``holder``'s rig and the sessions folder ``sessions``, behind the token gate for
    ``host:port``."""
    from starlette.applications import Starlette
    from starlette.concurrency import run_in_threadpool
    from starlette.middleware import Middleware

    from rangekit.ui.guard.headers import page_policy
    from rangekit.ui.guard.tickets import Tickets
    from rangekit.ui.jobs.calibrate import CalibrateJob
    from rangekit.ui.jobs.check import CheckJob
    from rangekit.ui.jobs.notifier import Notifier, Topic
    from rangekit.ui.jobs.recorded import RecordedCalibrationJob
    from rangekit.ui.jobs.register import RegisterJob
    from rangekit.ui.jobs.scan import ScanJob
    from rangekit.ui.routes import calibrate, check, common, events, jobs, page, register, rig, scan
    from rangekit.ui.routes import sessions as sessions_routes
    from rangekit.ui.routes import stream as stream_routes
    from rangekit.ui.stream import LiveStream

    live, notifier = LiveStream(holder), Notifier()
    holder.on_change = lambda: notifier.changed(Topic.RIG)
    ui = common.Ui(holder=holder, sessions=sessions, stream=live, check=CheckJob(holder, notifier),
                   calibration=CalibrateJob(holder, live, notifier), recorded=RecordedCalibrationJob(sessions, notifier),
                   registration=RegisterJob(sessions, notifier), scans=ScanJob(sessions, obj, holder),
                   tickets=Tickets(), notifier=notifier)
    routes = [r for room in (rig, stream_routes, check, calibrate, scan, events, jobs, sessions_routes, register,
                             page) for r in room.routes(ui)]

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        live.close()
        await run_in_threadpool(ui.scans.close)
        holder.close()

    names = {host} | ({"localhost", "127.0.0.1"} if host in ("127.0.0.1", "localhost") else set())
    hosts = {f"{h}:{port}" for h in names}
    gate = Middleware(Gate, token=token, hosts=hosts, origins={f"http://{h}" for h in hosts},
                      page_csp=page_policy(page.STATIC / "index.html"), tickets=ui.tickets)
    return Starlette(routes=routes, lifespan=lifespan, middleware=[gate],
                     exception_handlers={RangekitError: common.error_response, OSError: common.error_response})


def start(holder: RigHolder, sock: socket.socket, host: str, sessions: Path, obj: str = "lumpy") -> UiServer:
    """The app for ``holder`` and ``sessions`` on the bound ``sock`` (:func:`bind`); it runs with :func:`serve`."""
    port = sock.getsockname()[1]
    token = new_token()
    shown = f"[{host}]" if ":" in host else host
    return UiServer(f"http://{shown}:{port}/?token={token}", token, make_app(holder, token, shown, port, sessions, obj),
                    host, port)


def serve(server: UiServer, sock: socket.socket) -> None:
    """Run until Ctrl-C (uvicorn's own handling: the open pages are closed, the rig released), within the bounds
    of :mod:`rangekit.ui.guard.connections`."""
    import uvicorn

    from rangekit.ui.guard.connections import server_options

    config = uvicorn.Config(server.app, log_level="warning", access_log=False, lifespan="on",
                            ws_max_size=1 << 20, **server_options())
    uvicorn.Server(config).run(sockets=[sock])
