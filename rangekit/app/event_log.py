"""A session's ``events.jsonl``: the job's typed events (:mod:`rangekit.app.events`), one JSON object a line, as
it runs, in a child process or not; the one interface a watcher (the web app, a notebook, ``tail -f``) has to a
running job.

- :func:`to_json` / :func:`from_json`: the serialisation of every event type, in this one place. A line is
  ``{"type": "ViewDecoded", "index": 3, "total": 12, "name": "view_003", "points": 81234}``: never a cloud or a mesh
  inline (their counts, names and paths), a pose as 16 numbers (row-major), paths as strings, seconds and metres.
- :class:`EventLog`: a subscriber appending each event to ``FOLDER/events.jsonl``, a line written and flushed at a
  time (the file opened, appended and closed per line: nothing buffered, nothing to close), across a resume too.
  Events that come before the folder exists (a new scan's set-up) wait in memory until it does. Each line ends
  with ``"t"``: the seconds from the job's start (the log's making, :func:`logged`) to the event's publishing on
  the job's bus (:func:`rangekit.app.bus.published_at`; monotonic), so a scan can be placed step by step after its
  last frame; a resumed scan's or a later ``rangekit process``'s lines count from their own start. Lines without it
  (an older rangekit's, the web app's :class:`JobLaunched`...) read as well.
- :func:`logged`: the scan's and the processing's subscriber with the log in front (a chain already logging into
  that folder is returned as it is, so a scan's processing writes each event once).
- :func:`read_events`: the complete lines from a byte offset on, typed, with the offset after each (a watcher
  follows the file by calling it again from the last offset; a line still being written is left for the next
  call); :func:`read_timeline`: the whole file as ``(t, event)``, ``t`` None where a line has no time.
- The events of the process that runs a job as a child (the web app): :class:`JobLaunched`, :class:`JobPaused`,
  :class:`JobExited`, which that process appends to the same file before, during and after the child.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Iterator

import numpy as np

from rangekit.app import events as ev
from rangekit.app.bus import published_at
from rangekit.errors import FileFormatError
from rangekit.formats.sessions.files import EVENTS_FILE

__all__ = ["EventLog", "JobExited", "JobLaunched", "JobPaused", "LoggedCloud", "LoggedError",
           "LoggedMesh", "append_event", "from_json", "logged", "read_events", "read_timeline", "to_json"]

#: The file's name in a session folder (listed in :data:`rangekit.formats.output_sets.OUTPUT_SETS`).
#: The longest line read back (bytes): a longer one is refused as not a log of this kind.
MAX_LINE_BYTES = 1 << 20


@dataclass(frozen=True)
class JobLaunched:
    """A process (the web app) started ``command`` (``"scan"``, ``"resume"``, ``"process"``) as a child on this
    session; its events follow."""

    command: str


@dataclass(frozen=True)
class JobPaused:
    """The child was frozen (``paused`` True, SIGSTOP) or let go on (False)."""

    paused: bool


@dataclass(frozen=True)
class JobExited:
    """The child ended with ``exit_code`` (0 done, 130 stopped by Ctrl-C, 1 or 2 an error); ``last_lines``: the
    end of what it printed, for a person reading why it failed (empty when it succeeded)."""

    exit_code: int
    last_lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class LoggedCloud:
    """A cloud as the log keeps it: its number of points (``len()`` as a :class:`PointCloud`'s)."""

    points: int

    def __len__(self) -> int:
        return self.points


@dataclass(frozen=True)
class LoggedMesh:
    """A mesh as the log keeps it: its numbers of vertices and triangles."""

    vertices: int
    triangles: int


class LoggedError(Exception):
    """A :class:`JobFailed`'s error read back: ``kind`` its type's name, ``str()`` its one-line message."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


_TYPES = {cls.__name__: cls for cls in (ev.StageStarted, ev.StageFinished, ev.Progress, ev.ScanStarted,
                                         ev.FramesWritten, ev.ViewAcquired, ev.CaptureLoad, ev.ViewDecoded,
                                         ev.ViewPlaced, ev.PairRegistered, ev.MeshStarted, ev.MeshReady,
                                         ev.JobFailed, JobLaunched, JobPaused, JobExited)}
#: The key of a line's time (module doc): seconds from the job's start, 0.1 ms.
TIME_KEY = "t"
_PATHS = {"folder", "path"}


def _value(name: str, value):
    """One field as JSON: a path as a string, a cloud its count, a pose its 16 numbers, a tuple a list."""
    if isinstance(value, Path):
        return str(value)
    if name == "cloud":
        return len(value)
    if name == "T_world_view":
        return [float(x) for x in np.asarray(value, dtype=float).reshape(16)]
    if isinstance(value, tuple):
        return list(value)
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return value.item()
    return value


def to_json(event) -> dict:
    """``event`` as a JSON object: ``{"type": class name, field: value...}`` (module doc: no cloud or mesh inline;
    ``ViewDecoded.cloud`` and ``ViewPlaced.cloud`` become ``"points"``, ``MeshReady.mesh`` ``"vertices"`` and
    ``"triangles"``, ``JobFailed.error`` ``"error"`` (one line) and ``"kind"`` (its type))."""
    name = type(event).__name__
    if _TYPES.get(name) is not type(event):
        raise TypeError(f"event: expected one of {', '.join(_TYPES)}, found {type(event).__name__}")
    out: dict = {"type": name}
    for f in fields(event):
        value = getattr(event, f.name)
        if f.name == "cloud":
            out["points"] = len(value)
        elif f.name == "mesh":
            out["vertices"] = len(value.vertices)
            out["triangles"] = len(value.triangles)
        elif f.name == "error":
            out["error"] = " ".join(str(value).split()) or type(value).__name__
            out["kind"] = type(value).__name__ if not isinstance(value, LoggedError) else value.kind
        else:
            out[f.name] = _value(f.name, value)
    return out


def from_json(data: dict):
    """The typed event of a :func:`to_json` object (clouds as :class:`LoggedCloud`, meshes :class:`LoggedMesh`,
    the pose a (4, 4) array, an error a :class:`LoggedError`); FileFormatError for anything else."""
    cls = _TYPES.get(data.get("type")) if isinstance(data, dict) else None
    if cls is None:
        found = data.get("type") if isinstance(data, dict) else data
        raise FileFormatError(f"{EVENTS_FILE}: type: expected one of {', '.join(_TYPES)}, found {found!r:.80}")
    kwargs = {}
    try:
        for f in fields(cls):
            if f.name == "cloud":
                kwargs["cloud"] = LoggedCloud(int(data["points"]))
            elif f.name == "mesh":
                kwargs["mesh"] = LoggedMesh(int(data["vertices"]), int(data["triangles"]))
            elif f.name == "error":
                kwargs["error"] = LoggedError(str(data.get("kind", "Exception")), str(data["error"]))
            elif f.name == "T_world_view":
                kwargs[f.name] = np.asarray(data[f.name], dtype=float).reshape(4, 4)
            elif f.name in _PATHS:
                kwargs[f.name] = Path(data[f.name])
            elif f.name in data:
                value = data[f.name]
                kwargs[f.name] = tuple(value) if isinstance(value, list) else value
    except (KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"{EVENTS_FILE}: a {cls.__name__} line: {type(exc).__name__}: {exc}"[:300]) from None
    return cls(**kwargs)


def append_event(folder: str | Path, event) -> None:
    """Append ``event``'s line to ``folder``'s events.jsonl (a process other than the job's: the web app)."""
    with open(Path(folder) / EVENTS_FILE, "a", encoding="utf-8") as f:
        f.write(json.dumps(to_json(event), allow_nan=False) + "\n")


class EventLog:
    """The subscriber writing ``folder/events.jsonl``: each event a line, appended and flushed as it comes
    (module doc). Thread-safe: events come from the capture's, the frame writer's and the job's threads."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.start = time.monotonic()          # the job's start: each line's time counts from it (module doc)
        self._lock = threading.Lock()
        self._waiting: list[str] = []

    @property
    def path(self) -> Path:
        return self.folder / EVENTS_FILE

    def __call__(self, event) -> None:
        at = published_at()                     # on the bus's thread: when it was published, else now
        data = to_json(event)
        data[TIME_KEY] = round((time.monotonic() if at is None else at) - self.start, 4)
        line = json.dumps(data, allow_nan=False) + "\n"
        with self._lock:
            if not self.folder.is_dir():          # a new scan's set-up: the folder is made a moment later
                self._waiting.append(line)
                return
            lines, self._waiting = [*self._waiting, line], []
            with open(self.path, "a", encoding="utf-8") as f:
                f.write("".join(lines))


class _Chain:
    """The log, then the caller's subscriber (if any)."""

    def __init__(self, log: EventLog, then) -> None:
        self.log, self.then = log, then

    def __call__(self, event) -> None:
        self.log(event)
        if self.then is not None:
            self.then(event)


def logged(folder: str | Path, on_event):
    """``on_event`` with ``folder``'s :class:`EventLog` in front; a chain already logging there as it is, and so an
    event bus one of whose subscribers is such a chain (:attr:`rangekit.app.bus.EventBus.subscribers`: a scan's
    processing is given the scan's bus)."""
    for chain in getattr(on_event, "subscribers", (on_event,)):
        if isinstance(chain, _Chain) and chain.log.folder == Path(folder):
            return on_event
    return _Chain(EventLog(folder), on_event)


def read_events(path: str | Path, offset: int = 0, *, typed: bool = True) -> Iterator[tuple[object, int]]:
    """``(event, end)`` for each complete line of the events file ``path`` from byte ``offset`` on, ``end`` the
    offset just after that line (where to go on from); typed events (:func:`from_json`), or with ``typed=False``
    the JSON objects as written. A file not there yet has no events; a last line without its newline is being
    written, and waits for the next call."""
    try:
        with open(path, "rb") as f:
            f.seek(offset)
            data = f.read()
    except FileNotFoundError:
        return
    at = offset
    for raw in data.splitlines(keepends=True):
        if not raw.endswith(b"\n"):
            return
        if len(raw) > MAX_LINE_BYTES:
            raise FileFormatError(f"{path}: a line of {len(raw)} bytes at offset {at}; expected at most "
                                  f"{MAX_LINE_BYTES}")
        at += len(raw)
        try:
            obj = json.loads(raw)
        except ValueError:
            raise FileFormatError(f"{path}: the line at offset {at - len(raw)} is not JSON") from None
        yield (from_json(obj) if typed else obj), at


def read_timeline(path: str | Path) -> list[tuple[float | None, object]]:
    """Every complete line of the events file ``path`` as ``(t, event)``: ``t`` the seconds from its job's start to
    the event (module doc; None for a line without a time), ``event`` typed (:func:`from_json`)."""
    return [(obj.get(TIME_KEY), from_json(obj)) for obj, _ in read_events(path, typed=False)]
