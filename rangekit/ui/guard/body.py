"""A request's JSON body, read with bounds: its size (:data:`MAX_BODY_BYTES`, refused with 413 from its
Content-Length before a byte is read, or as soon as a streamed body passes it), the time it takes to arrive, its
nesting (a body nested too deep is a 400, never Python's RecursionError), and its shape (one JSON object)."""

from __future__ import annotations

import asyncio
import json

from rangekit.errors import RangekitError

__all__ = ["BODY_TIMEOUT_S", "MAX_BODY_BYTES", "BodyRefused", "read_json"]

#: The largest request body accepted (bytes): the app's requests are a few hundred bytes.
MAX_BODY_BYTES = 1 << 20
#: Seconds a body may take to arrive once its headers have.
BODY_TIMEOUT_S = 20.0


class BodyRefused(RangekitError):
    """A request body refused before it was used; ``status``: the HTTP status to answer with."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


def too_large(length: int | None = None) -> str:
    said = "" if length is None else f" ({length} bytes)"
    return f"request body too large{said}: at most {MAX_BODY_BYTES} bytes"


async def _read(request) -> bytes:
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY_BYTES:
            raise BodyRefused(too_large(), 413)
        chunks.append(chunk)
    return b"".join(chunks)


async def read_json(request) -> dict:
    """The body of ``request`` as a dict (an empty body: ``{}``); :class:`BodyRefused` with one line otherwise."""
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > MAX_BODY_BYTES):
        raise BodyRefused(too_large(int(length) if length.isdigit() else None), 413)
    try:
        raw = await asyncio.wait_for(_read(request), BODY_TIMEOUT_S)
    except asyncio.TimeoutError:
        raise BodyRefused(f"request body: not received within {BODY_TIMEOUT_S:.0f} s", 408) from None
    try:
        data = json.loads(raw or b"{}")
    except RecursionError:
        raise BodyRefused("request: JSON nested too deep") from None
    except ValueError:
        raise BodyRefused("request: not JSON") from None
    if not isinstance(data, dict):
        raise BodyRefused("request: expected a JSON object")
    return data
