"""``rangekit ui``: the web app's server (Starlette on uvicorn, WebSockets for the live stream and the events).

Routes (every one behind :class:`rangekit.ui.access.Gate`: the token in its header, the app's own origin for a
change, the host; see there):

- ``GET /``: the page (``static/index.html``); its script keeps the ``?token=`` it was opened with;
- ``GET /static/...``: the page's scripts and styles, shipped in the package (no network);
- ``POST /api/ticket`` ``{"path"}``: a single-use ticket opening ``path`` once (the WebSocket, a report's iframe);
- ``GET /api/status``: the devices' status; ``POST /api/reconnect`` (hardware: open the devices again); ``POST /api/pattern`` ``{"name"}``; ``POST /api/turntable``
  ``{"degrees"}`` or ``{"home": true}``; ``POST /api/camera`` ``{"exposure_us", "iso", "white_balance_k",
  "focus"}`` (any of them: written into the rig file's ``capture.camera``, then applied);
- ``GET /api/check`` (the latest check: idle, running with its progress, done, failed), ``POST /api/check/run``,
  ``POST /api/check/apply`` (its suggested rig-file changes written), ``GET /api/check/figure.png``;
- ``GET /api/calibrate`` (the calibration wizard: its state, poses, hint, result), ``POST
  /api/calibrate/ACTION`` (start ``{"poses", "seed"}``, capture, keep, retake, next, drag ``{"dx", "dy"}``,
  cancel), ``GET /api/calibrate/picture/coverage.png`` and ``tilts.png``; ``GET /api/calibrate-recorded``, ``POST
  /api/calibrate-recorded/start`` ``{"captures", "pattern", "projector", "out", "cols", "rows", "square_mm",
  "replace"}``
  (recorded pose folders under ``--sessions``);
- ``GET /api/options`` (the scan's and the processing's ranges and defaults, from their dataclasses:
  :func:`rangekit.ui.scan_job.option_limits`), ``GET /api/scan`` (the scan: running, its views, files, last lines), ``POST /api/scan/start`` ``{"name",
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
Every JSON field is type-checked first (:mod:`rangekit.ui.guard.fields`), the body bounded
(:mod:`rangekit.ui.guard.body`), and every device call and file access runs off the event loop (Starlette's
thread pool), so a turning turntable never stalls another page's request.
"""

from __future__ import annotations

import contextlib
import json
import socket
from dataclasses import dataclass
from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.access import Gate, new_token
from rangekit.ui.calibrate_job import CalibrateJob
from rangekit.ui.check_job import CheckJob
from rangekit.ui.guard.body import BodyRefused, read_json
from rangekit.ui.guard.fields import Field, flag, number, take, text, texts
from rangekit.ui.guard.headers import page_policy
from rangekit.ui.guard.names import check_folder_name
from rangekit.ui.paths import confined
from rangekit.ui.recorded_job import RecordedCalibrationJob
from rangekit.ui.register_job import RegisterJob, list_clouds
from rangekit.ui.scan_job import ScanJob, option_limits, view_points
from rangekit.ui.sessions_list import session_file, sessions_listing
from rangekit.ui.rig_holder import PATTERNS, RigHolder
from rangekit.ui.stream import LiveStream

__all__ = ["UiServer", "bind", "make_app"]

STATIC = Path(__file__).resolve().parent / "static"
#: The camera controls the Live page sets (the rig file's capture.camera fields).
CAMERA_FIELDS = ("exposure_us", "iso", "white_balance_k", "focus")
#: The largest turntable jog (degrees, either way).
MAX_JOG_DEG = 360.0
#: The live streams open at once (each holds a thread of the pool while it waits for a frame).
MAX_STREAMS = 8


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


def _json(data, status: int = 200):
    from starlette.responses import JSONResponse

    return JSONResponse(data, status_code=status, headers={"Cache-Control": "no-store"})


def _os_error(exc: OSError) -> str:
    name = Path(exc.filename).name if isinstance(exc.filename, str) else "file"
    return f"{name[:80]}: {exc.strerror or exc}"


def _given(default=None) -> Field:
    """A field whose job checks its type and range itself (with the words the page shows by the field)."""
    return Field(lambda name, value: value, default)


def _camera_value(name, value):
    if isinstance(value, (bool, list, dict)) or value is None:
        raise RangekitError(f"camera: {name}: expected a number or 'auto', found {value!r}"[:200])
    return value


async def _answer(call, *args, status_for_refusal: int = 400):
    """``call(*args)`` on the thread pool, its result as JSON (or as the Response it is); a refusal as one line."""
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import Response

    try:
        result = await run_in_threadpool(call, *args)
    except RangekitError as exc:
        return _json({"error": str(exc)}, status_for_refusal)
    except OSError as exc:
        return _json({"error": _os_error(exc)}, status_for_refusal)
    return result if isinstance(result, Response) else _json(result)


def _action(what: str, spec: dict, act):
    """A POST endpoint: its JSON body read within bounds, its fields checked by ``spec``, then
    ``act(request, fields)`` on the thread pool."""
    async def endpoint(request):
        try:
            fields = take(await read_json(request), spec, what)
        except BodyRefused as exc:
            return _json({"error": str(exc)}, exc.status)
        except RangekitError as exc:
            return _json({"error": str(exc)}, 400)
        return await _answer(act, request, fields)
    return endpoint


def _reading(act, status_for_refusal: int = 400):
    """A GET endpoint: ``act(request)`` on the thread pool."""
    async def endpoint(request):
        return await _answer(act, request, status_for_refusal=status_for_refusal)
    return endpoint


def _png(data: bytes | None, missing: str):
    from starlette.responses import Response

    if not data:
        return _json({"error": missing}, 404)
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})


def _binary(data: bytes):
    from starlette.responses import Response

    return Response(data, media_type="application/octet-stream", headers={"Cache-Control": "no-store"})


def make_app(holder: RigHolder, token: str, host: str, port: int, sessions: Path, obj: str = "lumpy"):
    """The Starlette app for ``holder``'s rig and the sessions folder ``sessions``, behind the token gate for
    ``host:port``."""
    from starlette.applications import Starlette
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import FileResponse
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles
    from starlette.websockets import WebSocketDisconnect

    stream = LiveStream(holder)
    check = CheckJob(holder)
    calibration = CalibrateJob(holder, stream)
    recorded = RecordedCalibrationJob(sessions)
    registration = RegisterJob(sessions)
    scans = ScanJob(sessions, obj, holder)
    gate: Gate | None = None      # set below: the ticket route issues its tickets
    streams = {"open": 0}

    async def index(request):
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    def rig(*_):
        return {"rig": holder.status()}

    def status(request):
        return {"rig": holder.status(), "patterns": list(PATTERNS), "live_error": stream.error}

    def ticket(request, f):
        path = f["path"]
        if path != "/ws/live" and not (path.startswith("/api/sessions/") and "/files/" in path):
            raise RangekitError(f"path: {path[:80]!r}: no ticket for it; expected /ws/live or a session's file")
        return {"ticket": gate.tickets.issue(path)}

    def pattern(request, f):
        holder.show_pattern(f["name"])
        return rig()

    def turntable(request, f):
        if f["home"]:
            holder.turn(home=True)
        elif f["degrees"] is None:
            raise RangekitError(f"degrees: missing; expected a number -{MAX_JOG_DEG:g} to {MAX_JOG_DEG:g} "
                                "(or home: true)")
        else:
            holder.turn(degrees=f["degrees"])
        return rig()

    def camera(request, f):
        holder.set_camera(f)
        return rig()

    async def camera_endpoint(request):
        try:
            body = await read_json(request)
        except BodyRefused as exc:
            return _json({"error": str(exc)}, exc.status)
        unknown = sorted(set(body) - set(CAMERA_FIELDS))
        if unknown:
            return _json({"error": f"camera: {str(unknown[0])[:80]}: not a control here; expected "
                                   f"{', '.join(CAMERA_FIELDS)}"}, 400)
        spec = {name: Field(_camera_value, None) for name in CAMERA_FIELDS}
        try:
            fields = {k: v for k, v in take(body, spec, "camera").items() if k in body}
        except RangekitError as exc:
            return _json({"error": str(exc)}, 400)
        return await _answer(camera, request, fields)

    def calibrate_action(request, f):
        action = request.path_params["action"]
        if action == "start":
            return calibration.start(f["poses"], f["seed"])
        if action == "drag":
            return calibration.drag(f["dx"], f["dy"])
        acts = {"capture": calibration.capture, "keep": lambda: calibration.decide(True),
                "retake": lambda: calibration.decide(False), "next": calibration.next_pose,
                "cancel": calibration.cancel}
        return acts[action]()

    async def calibrate_endpoint(request):
        action = request.path_params["action"]
        specs = {"start": {"poses": _given(12), "seed": _given(0)}, "drag": {"dx": _given(), "dy": _given()},
                 **{a: {} for a in ("capture", "keep", "retake", "next", "cancel")}}
        if action not in specs:
            return _json({"error": f"calibrate: {action[:40]}: unknown; expected start, capture, keep, retake, "
                                   "next, drag or cancel"}, 404)
        return await _action(f"calibrate {action}", specs[action], calibrate_action)(request)

    def recorded_start(request, f):
        return recorded.start(f["captures"], f["pattern"], f["projector"], f["out"], f["cols"], f["rows"],
                              f["square_mm"], replace=f["replace"])

    def register_save(request, f):
        return registration.save(check_folder_name(f["name"]))

    def scan_start(request, f):
        return scans.start(check_folder_name(f["name"]), f["views"], resume=f["resume"])

    def session_process(request, f):
        return scans.process(request.path_params["name"], fusion=f["fusion"], mesh_format=f["format"],
                             report=f["report"])

    def session_export(request, f):
        from rangekit.app.process.fused_outputs import export_meshes

        folder = confined(sessions, request.path_params["name"])
        if scans.running and scans.name == folder.name:
            raise RangekitError(f"{folder.name} is being scanned or processed; export when it has finished")
        return {"files": export_meshes(folder, f["format"])}

    def sessions_file(request):
        path = session_file(sessions, request.path_params["name"], request.path_params["file"])
        return FileResponse(path, headers={"Cache-Control": "no-store"})

    async def live(ws):
        if streams["open"] >= MAX_STREAMS:
            await ws.close(code=1013, reason=f"at most {MAX_STREAMS} live streams at once")
            return
        await ws.accept()
        streams["open"] += 1
        stream.watch()
        seq = 0
        try:
            while True:
                frame = await run_in_threadpool(stream.next_after, seq, 1.0)
                if frame is None:
                    await ws.send_text(json.dumps({"waiting": holder.busy or stream.error or "no frame yet"}))
                    continue
                seq = frame.seq
                await ws.send_text(json.dumps(frame.figures()))
                await ws.send_bytes(frame.jpeg)
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass
        finally:
            streams["open"] -= 1
            stream.unwatch()

    post, get = (lambda path, what, spec, act: Route(path, _action(what, spec, act), methods=["POST"])), Route
    routes = [
        get("/", index), get("/api/status", _reading(status)),
        post("/api/ticket", "ticket", {"path": text()}, ticket),
        post("/api/pattern", "pattern", {"name": text()}, pattern),
        post("/api/reconnect", "reconnect", {}, lambda r, f: {"rig": holder.connect()}),
        post("/api/turntable", "turntable", {"degrees": number(-MAX_JOG_DEG, MAX_JOG_DEG, None),
                                             "home": flag(False)}, turntable),
        Route("/api/camera", camera_endpoint, methods=["POST"]),
        get("/api/check", _reading(lambda r: check.snapshot())),
        post("/api/check/run", "check", {}, lambda r, f: check.start()),
        post("/api/check/apply", "check apply", {}, lambda r, f: {"rig": check.apply()}),
        get("/api/check/figure.png", _reading(lambda r: _png(check.figure_png, "no check picture yet: run the check"))),
        get("/api/calibrate", _reading(lambda r: calibration.snapshot())),
        Route("/api/calibrate/{action}", calibrate_endpoint, methods=["POST"]),
        get("/api/calibrate/picture/{name}.png", _reading(lambda r: _png(
            calibration.pictures.get(r.path_params["name"]), "no such picture yet: capture a pose first"))),
        get("/api/calibrate-recorded", _reading(lambda r: recorded.snapshot())),
        post("/api/calibrate-recorded/start", "calibrate-recorded", {
            "captures": text(""), "pattern": text(""), "projector": text(""), "out": text("recorded-rig.json"),
            "cols": _given(10), "rows": _given(7), "square_mm": _given(20.0),
            "replace": flag(False)}, recorded_start),
        get("/api/register", _reading(lambda r: registration.snapshot())),
        get("/api/register/clouds", _reading(lambda r: {"clouds": list_clouds(sessions)})),
        get("/api/register/points/{index:int}", _reading(lambda r: _binary(registration.points(r.path_params["index"])))),
        post("/api/register/start", "register", {"files": texts(2000), "neighbours": _given(None)},
             lambda r, f: registration.start(f["files"], f["neighbours"])),
        post("/api/register/save", "register save", {"name": text()}, register_save),
        get("/api/scan", _reading(lambda r: scans.snapshot())),
        get("/api/options", _reading(lambda r: option_limits())),
        post("/api/scan/start", "scan", {"name": text(), "views": _given(option_limits()["scan"]["views"]["default"]),
                                         "resume": flag(False)}, scan_start),
        post("/api/scan/stop", "scan stop", {}, lambda r, f: scans.stop()),
        post("/api/scan/pause", "scan pause", {"paused": flag(True)}, lambda r, f: scans.pause(f["paused"])),
        post("/api/sessions/{name}/process", "process", {"fusion": text("poisson"), "format": text("ply"),
                                                         "report": flag(True)}, session_process),
        post("/api/sessions/{name}/export", "export", {"format": text("")}, session_export),
        get("/api/sessions/{name}/views/{index:int}/points", _reading(lambda r: _binary(view_points(
            confined(sessions, r.path_params["name"]), r.path_params["index"])))),
        get("/api/sessions", _reading(lambda r: sessions_listing(sessions))),
        get("/api/sessions/{name}/files/{file}", _reading(sessions_file, status_for_refusal=404)),
        WebSocketRoute("/ws/live", live), Mount("/static", StaticFiles(directory=STATIC), name="static")]

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        stream.close()
        await run_in_threadpool(scans.close)
        holder.close()

    app = Starlette(routes=routes, lifespan=lifespan)
    names = {host} | ({"localhost", "127.0.0.1"} if host in ("127.0.0.1", "localhost") else set())
    hosts = {f"{h}:{port}" for h in names}
    origins = {f"http://{h}" for h in hosts}
    gate = Gate(app, token, hosts, origins, page_policy(STATIC / "index.html"))
    return gate


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
