"""``rangekit ui``: the web app's server (Starlette on uvicorn, WebSockets for the live stream and the events).

Routes (every one behind :class:`rangekit.ui.access.Gate`: the token, the app's own origin and host):

- ``GET /``: the page (``static/index.html``); the ``?token=`` it was opened with is kept as a cookie;
- ``GET /static/...``: the page's scripts and styles, shipped in the package (no network);
- ``GET /api/status``: the devices' status; ``POST /api/reconnect`` (hardware: open the devices again); ``POST /api/pattern`` ``{"name"}``; ``POST /api/turntable``
  ``{"degrees"}`` or ``{"home": true}``; ``POST /api/camera`` ``{"exposure_us", "iso", "white_balance_k",
  "focus"}`` (any of them: written into the rig file's ``capture.camera``, then applied);
- ``GET /api/check`` (the latest check: idle, running with its progress, done, failed), ``POST /api/check/run``,
  ``POST /api/check/apply`` (its suggested rig-file changes written), ``GET /api/check/figure.png``;
- ``GET /api/calibrate`` (the calibration wizard: its state, poses, hint, result), ``POST
  /api/calibrate/ACTION`` (start ``{"poses", "seed"}``, capture, keep, retake, next, drag ``{"dx", "dy"}``,
  cancel), ``GET /api/calibrate/picture/coverage.png`` and ``tilts.png``; ``GET /api/calibrate-recorded``, ``POST
  /api/calibrate-recorded/start`` ``{"captures", "pattern", "projector", "out", "cols", "rows", "square_mm"}``
  (recorded pose folders under ``--sessions``);
- ``GET /api/scan`` (the scan: running, its views, files, last lines), ``POST /api/scan/start`` ``{"name",
  "views"}`` or ``{"name", "resume": true}``, ``POST /api/scan/stop``, ``POST /api/scan/pause`` ``{"paused"}``; ``GET
  /api/sessions/NAME/views/K/points`` (a decoded view's points, float32 x y z in mm);
- ``GET /api/sessions`` (each session under ``--sessions``: state, figures, files), ``GET
  /api/sessions/NAME/files/FILE`` (its report.html, meshes, poses.json, summary.json); ``POST
  /api/sessions/NAME/process`` ``{"fusion", "format", "report"}`` (``rangekit process`` again, as the Scan page's
  child), ``POST /api/sessions/NAME/export`` ``{"format"}`` (its meshes as obj, stl or glb beside the PLY);
- ``GET /api/register`` (the registration: its pairs' residuals), ``GET /api/register/clouds`` (the cloud files
  under ``--sessions``), ``POST /api/register/start`` ``{"files", "neighbours"}``, ``POST /api/register/save``
  ``{"name"}``, ``GET /api/register/points/K`` (cloud K placed by its registered pose, float32 mm);
- ``WS /ws/live``: the camera stream, each frame a text message (its figures, JSON) then a binary one (JPEG).

A request the rig refuses gets 400 and ``{"error": one line}``, the CLI's words; nothing else reaches the page.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
from dataclasses import dataclass
from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.access import COOKIE, Gate, new_token
from rangekit.ui.calibrate_job import CalibrateJob
from rangekit.ui.check_job import CheckJob
from rangekit.ui.paths import confined
from rangekit.ui.recorded_job import RecordedCalibrationJob
from rangekit.ui.register_job import RegisterJob, list_clouds
from rangekit.ui.scan_job import ScanJob, view_points
from rangekit.ui.sessions_list import list_sessions, session_file
from rangekit.ui.rig_holder import PATTERNS, RigHolder
from rangekit.ui.stream import LiveStream

__all__ = ["UiServer", "bind", "make_app"]

STATIC = Path(__file__).resolve().parent / "static"
#: The camera controls the Live page sets (the rig file's capture.camera fields).
CAMERA_FIELDS = ("exposure_us", "iso", "white_balance_k", "focus")


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
    sock.listen(64)
    return sock


def _json(data, status: int = 200):
    from starlette.responses import JSONResponse

    return JSONResponse(data, status_code=status)


def _error(exc: Exception):
    return _json({"error": str(exc)}, 400)


async def _body(request) -> dict:
    try:
        data = json.loads(await request.body() or b"{}")
    except ValueError:
        raise RangekitError("request: not JSON") from None
    if not isinstance(data, dict):
        raise RangekitError("request: expected a JSON object")
    return data


def make_app(holder: RigHolder, token: str, host: str, port: int, sessions: Path, obj: str = "lumpy"):
    """The Starlette app for ``holder``'s rig and the sessions folder ``sessions``, behind the token gate for
    ``host:port``."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, Response
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles
    from starlette.websockets import WebSocketDisconnect

    stream = LiveStream(holder)
    check = CheckJob(holder)
    calibration = CalibrateJob(holder, stream)
    recorded = RecordedCalibrationJob(sessions)
    registration = RegisterJob(sessions)
    scans = ScanJob(sessions, obj, holder)

    async def index(request):
        response = FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})
        if "token" in request.query_params:     # checked by the gate: kept for the page's own requests
            response.set_cookie(COOKIE, request.query_params["token"], httponly=True, samesite="strict")
        return response

    async def status(request):
        return _json({"rig": holder.status(), "patterns": list(PATTERNS), "live_error": stream.error})

    async def reconnect(request):
        try:
            return _json({"rig": await asyncio.to_thread(holder.connect)})
        except RangekitError as exc:
            return _error(exc)

    async def pattern(request):
        try:
            body = await _body(request)
            await asyncio.to_thread(holder.show_pattern, str(body.get("name")))
        except RangekitError as exc:
            return _error(exc)
        return _json({"rig": holder.status()})

    async def turntable(request):
        try:
            body = await _body(request)
            if body.get("home"):
                await asyncio.to_thread(holder.turn, home=True)
            else:
                degrees = body.get("degrees")
                if isinstance(degrees, bool) or not isinstance(degrees, (int, float)):
                    raise RangekitError(f"degrees: expected a number, found {degrees!r}")
                await asyncio.to_thread(holder.turn, degrees=float(degrees))
        except RangekitError as exc:
            return _error(exc)
        return _json({"rig": holder.status()})

    async def camera(request):
        try:
            body = await _body(request)
            unknown = sorted(set(body) - set(CAMERA_FIELDS))
            if unknown:
                raise RangekitError(f"camera: {unknown[0]}: not a control here; expected {', '.join(CAMERA_FIELDS)}")
            await asyncio.to_thread(holder.set_camera, body)
        except RangekitError as exc:
            return _error(exc)
        return _json({"rig": holder.status()})

    async def check_state(request):
        return _json(check.snapshot())

    async def check_start(request):
        try:
            return _json(check.start())
        except RangekitError as exc:
            return _error(exc)

    async def check_apply(request):
        try:
            return _json({"rig": await asyncio.to_thread(check.apply)})
        except RangekitError as exc:
            return _error(exc)

    async def check_figure(request):
        if check.figure_png is None:
            return _json({"error": "no check picture yet: run the check"}, 404)
        return Response(check.figure_png, media_type="image/png", headers={"Cache-Control": "no-store"})

    async def calibrate_state(request):
        return _json(calibration.snapshot())

    async def calibrate_action(request):
        action = request.path_params["action"]
        try:
            body = await _body(request)
            if action == "start":
                result = calibration.start(body.get("poses", 12), body.get("seed", 0))
            elif action == "capture":
                result = calibration.capture()
            elif action in ("keep", "retake"):
                result = calibration.decide(action == "keep")
            elif action == "next":
                result = await asyncio.to_thread(calibration.next_pose)
            elif action == "drag":
                result = await asyncio.to_thread(calibration.drag, body.get("dx"), body.get("dy"))
            elif action == "cancel":
                result = calibration.cancel()
            else:
                return _json({"error": f"calibrate: {action}: unknown; expected start, capture, keep, retake, next, "
                                       "drag or cancel"}, 404)
        except RangekitError as exc:
            return _error(exc)
        return _json(result)

    async def calibrate_picture(request):
        png = calibration.pictures.get(request.path_params["name"])
        if not png:
            return _json({"error": "no such picture yet: capture a pose first"}, 404)
        return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})

    async def recorded_state(request):
        return _json(recorded.snapshot())

    async def recorded_start(request):
        try:
            body = await _body(request)
            return _json(await asyncio.to_thread(
                recorded.start, body.get("captures", ""), body.get("pattern"), body.get("projector", ""),
                body.get("out", "recorded-rig.json"), body.get("cols", 10), body.get("rows", 7),
                body.get("square_mm", 20.0)))
        except RangekitError as exc:
            return _error(exc)

    async def register_state(request):
        return _json(registration.snapshot())

    async def register_clouds(request):
        return _json({"clouds": await asyncio.to_thread(list_clouds, sessions)})

    async def register_action(request):
        try:
            body = await _body(request)
            if request.path_params["action"] == "start":
                return _json(await asyncio.to_thread(registration.start, body.get("files"), body.get("neighbours")))
            if request.path_params["action"] == "save":
                return _json(await asyncio.to_thread(registration.save, str(body.get("name", ""))))
        except RangekitError as exc:
            return _error(exc)
        return _json({"error": "register: expected start or save"}, 404)

    async def register_points(request):
        try:
            data = await asyncio.to_thread(registration.points, int(request.path_params["index"]))
        except (RangekitError, ValueError) as exc:
            return _error(exc)
        return Response(data, media_type="application/octet-stream")

    async def scan_state(request):
        return _json(await asyncio.to_thread(scans.snapshot))

    async def scan_start(request):
        try:
            body = await _body(request)
            resume = bool(body.get("resume"))
            return _json(await asyncio.to_thread(scans.start, str(body.get("name", "")), body.get("views", 6),
                                                 resume=resume))
        except RangekitError as exc:
            return _error(exc)

    async def scan_stop(request):
        try:
            return _json(scans.stop())
        except RangekitError as exc:
            return _error(exc)

    async def scan_pause(request):
        try:
            body = await _body(request)
            return _json(scans.pause(bool(body.get("paused", True))))
        except RangekitError as exc:
            return _error(exc)

    async def session_process(request):
        try:
            body = await _body(request)
            return _json(await asyncio.to_thread(scans.process, request.path_params["name"],
                                                 fusion=body.get("fusion", "poisson"),
                                                 mesh_format=body.get("format", "ply"), report=body.get("report", True)))
        except RangekitError as exc:
            return _error(exc)

    async def session_export(request):
        from rangekit.app.process.fused_outputs import export_meshes

        try:
            body = await _body(request)
            folder = confined(sessions, request.path_params["name"])
            if scans.running and scans.name == folder.name:
                raise RangekitError(f"{folder.name} is being scanned or processed; export when it has finished")
            files = await asyncio.to_thread(export_meshes, folder, str(body.get("format")))
        except RangekitError as exc:
            return _error(exc)
        return _json({"files": files})

    async def scan_points(request):
        try:
            folder = confined(sessions, request.path_params["name"])
            data = await asyncio.to_thread(view_points, folder, int(request.path_params["index"]))
        except (RangekitError, ValueError) as exc:
            return _error(exc)
        return Response(data, media_type="application/octet-stream")

    async def sessions_list(request):
        return _json({"sessions": await asyncio.to_thread(list_sessions, sessions)})

    async def sessions_file(request):
        try:
            path = session_file(sessions, request.path_params["name"], request.path_params["file"])
        except RangekitError as exc:
            return _json({"error": str(exc)}, 404)
        return FileResponse(path, headers={"Cache-Control": "no-store"})

    async def live(ws):
        await ws.accept()
        stream.watch()
        seq = 0
        try:
            while True:
                frame = await asyncio.to_thread(stream.next_after, seq, 1.0)
                if frame is None:
                    await ws.send_text(json.dumps({"waiting": holder.busy or stream.error or "no frame yet"}))
                    continue
                seq = frame.seq
                await ws.send_text(json.dumps(frame.figures()))
                await ws.send_bytes(frame.jpeg)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            stream.unwatch()

    routes = [Route("/", index), Route("/api/status", status), Route("/api/pattern", pattern, methods=["POST"]),
              Route("/api/reconnect", reconnect, methods=["POST"]),
              Route("/api/turntable", turntable, methods=["POST"]), Route("/api/camera", camera, methods=["POST"]),
              Route("/api/check", check_state), Route("/api/check/run", check_start, methods=["POST"]),
              Route("/api/check/apply", check_apply, methods=["POST"]), Route("/api/check/figure.png", check_figure),
              Route("/api/calibrate", calibrate_state),
              Route("/api/calibrate/{action}", calibrate_action, methods=["POST"]),
              Route("/api/calibrate/picture/{name}.png", calibrate_picture),
              Route("/api/calibrate-recorded", recorded_state),
              Route("/api/calibrate-recorded/start", recorded_start, methods=["POST"]),
              Route("/api/register", register_state), Route("/api/register/clouds", register_clouds),
              Route("/api/register/points/{index}", register_points),
              Route("/api/register/{action}", register_action, methods=["POST"]),
              Route("/api/scan", scan_state), Route("/api/scan/start", scan_start, methods=["POST"]),
              Route("/api/scan/stop", scan_stop, methods=["POST"]),
              Route("/api/scan/pause", scan_pause, methods=["POST"]),
              Route("/api/sessions/{name}/process", session_process, methods=["POST"]),
              Route("/api/sessions/{name}/export", session_export, methods=["POST"]),
              Route("/api/sessions/{name}/views/{index}/points", scan_points),
              Route("/api/sessions", sessions_list), Route("/api/sessions/{name}/files/{file}", sessions_file), WebSocketRoute("/ws/live", live),
              Mount("/static", StaticFiles(directory=STATIC), name="static")]
    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        stream.close()
        await asyncio.to_thread(scans.close)
        holder.close()

    app = Starlette(routes=routes, lifespan=lifespan)
    names = {host} | ({"localhost", "127.0.0.1"} if host in ("127.0.0.1", "localhost") else set())
    hosts = {f"{h}:{port}" for h in names}
    origins = {f"http://{h}" for h in hosts}
    return Gate(app, token, hosts, origins)


def start(holder: RigHolder, sock: socket.socket, host: str, sessions: Path, obj: str = "lumpy") -> UiServer:
    """The app for ``holder`` and ``sessions`` on the bound ``sock`` (:func:`bind`); it runs with :func:`serve`."""
    port = sock.getsockname()[1]
    token = new_token()
    shown = f"[{host}]" if ":" in host else host
    return UiServer(f"http://{shown}:{port}/?token={token}", token, make_app(holder, token, shown, port, sessions, obj),
                    host, port)


def serve(server: UiServer, sock: socket.socket) -> None:
    """Run until Ctrl-C (uvicorn's own handling: the open pages are closed, the rig released)."""
    import uvicorn

    config = uvicorn.Config(server.app, log_level="warning", access_log=False, lifespan="on",
                            ws_max_size=1 << 20)
    uvicorn.Server(config).run(sockets=[sock])
