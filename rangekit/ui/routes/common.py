"""What every route module of the web app shares: :class:`Ui` (the app's rig, jobs and folders), the one
exception handler (:func:`error_response`: ``{"error": one line, "field": the request field it names}`` as JSON,
as jupyter_server's ``APIHandler.write_error`` answers), and the two ways an endpoint runs its work off the event
loop: :func:`action` (a POST: its JSON body read within bounds, its fields checked) and :func:`reading` (a GET).

A request the rig refuses gets 400 (404 for a file that is not there, 413 for a body too large, the status of
:class:`rangekit.ui.guard.body.BodyRefused`) and ``{"error": one line}``, the CLI's words, with ``"field"`` when the
line names one of the request's fields (``views: expected a whole number 2-360, found 1``: ``"views"``); a bug is
a 500 with one line naming it, its traceback in the server's log. Nothing else reaches the page.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.progress import LOGGER
from rangekit.ui.guard.body import read_json
from rangekit.ui.guard.fields import Field, take

__all__ = ["Ui", "action", "binary", "error_response", "field_of", "given", "json_response", "png", "reading"]


@dataclass(frozen=True)
class Ui:
    """The app's state the routes share: the rig holder, the live stream, the jobs, the sessions folder, the
    tickets the Gate redeems, the notifier the jobs and the rig say their changes on
    (:class:`rangekit.ui.jobs.notifier.Notifier`)."""

    holder: object
    sessions: Path
    stream: object
    check: object
    calibration: object
    recorded: object
    registration: object
    scans: object
    tickets: object
    notifier: object


def json_response(data, status: int = 200):
    from starlette.responses import JSONResponse

    return JSONResponse(data, status_code=status, headers={"Cache-Control": "no-store"})


def field_of(message: str, names) -> str | None:
    """The request field ``message`` names: the first of ``names`` written as ``NAME:`` (at the start, after a
    space or a dot: ``capture.camera.iso: ...``), or None."""
    found = [(m.start(), name) for name in names
             if (m := re.search(rf"(?:^|[ .]){re.escape(name)}:", message)) is not None]
    return min(found)[1] if found else None


def _os_error(exc: OSError) -> str:
    name = Path(exc.filename).name if isinstance(exc.filename, str) else "file"
    return f"{name[:80]}: {exc.strerror or exc}"


def error_response(request, exc: Exception):
    """The one answer to a failed request (module doc); also Starlette's exception handler for rangekit's errors
    and OSError."""
    state = getattr(request, "state", None)
    if isinstance(exc, RangekitError):
        message, status = str(exc), getattr(exc, "status", None) or getattr(state, "refusal_status", 400)
    elif isinstance(exc, OSError):
        message, status = _os_error(exc), getattr(state, "refusal_status", 400)
    else:
        LOGGER.error("%s %s failed", request.method, request.url.path, exc_info=exc)
        message, status = f"the server failed: {type(exc).__name__}", 500
    body = {"error": message}
    field = field_of(message, getattr(state, "fields", ()))
    if field is not None:
        body["field"] = field
    return json_response(body, status)


async def _answer(request, call, *args):
    """``call(*args)`` on the thread pool, its result as JSON (or as the Response it is); a failure as
    :func:`error_response`."""
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import Response

    try:
        result = await run_in_threadpool(call, *args)
    except Exception as exc:  # noqa: BLE001 - one answer for every failure (module doc)
        return error_response(request, exc)
    return result if isinstance(result, Response) else json_response(result)


def action(what: str, spec: dict[str, Field], act, *, checked: bool = True):
    """A POST endpoint: its JSON body read within bounds, its fields checked by ``spec``, then
    ``act(request, fields)`` on the thread pool (``checked`` False: ``act`` is given the body as read and checks
    it itself; ``spec`` then only names the fields an error may name)."""
    async def endpoint(request):
        request.state.fields = tuple(spec)
        try:
            body = await read_json(request)
            fields = take(body, spec, what) if checked else body
        except RangekitError as exc:
            return error_response(request, exc)
        return await _answer(request, act, request, fields)
    return endpoint


def reading(act, status_for_refusal: int = 400):
    """A GET endpoint: ``act(request)`` on the thread pool (a refusal answered with ``status_for_refusal``)."""
    async def endpoint(request):
        request.state.refusal_status = status_for_refusal
        return await _answer(request, act, request)
    return endpoint


def given(default=None) -> Field:
    """A field whose job checks its type and range itself (with the words the page shows by the field)."""
    return Field(lambda name, value: value, default)


def png(data: bytes | None, missing: str):
    from starlette.responses import Response

    if not data:
        return json_response({"error": missing}, 404)
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})


def binary(data: bytes):
    from starlette.responses import Response

    return Response(data, media_type="application/octet-stream", headers={"Cache-Control": "no-store"})


class NotThere(RangekitError):
    """A route's resource that does not exist (404)."""

    status = 404


__all__ += ["NotThere"]
