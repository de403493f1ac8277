"""A scan job as its events tell it (``events.jsonl``, :mod:`rangekit.app.event_log`): which views are taken and
decoded, the files written, whether the child runs, is paused or ended and how, its last lines for people. The
server's ``GET /api/scan`` is this fold; the page folds the same events itself (``static/scan.js``).

The file spans every run on the session (a resume appends): a view taken or decoded by an earlier run stays so;
whether the job runs, its pause and its end are read only from the events of the current launch (those after
byte ``start``, where the file ended when the app started the child).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from rangekit.app import events as ev
from rangekit.app.event_log import JobExited, JobPaused
from rangekit.formats.sessions.files import MESH_FILE, REPORT_FILE, SUMMARY_FILE, view_name

__all__ = ["ScanView"]

#: The lines for people kept (the Progress events' messages, the failure).
KEPT_LINES = 30


@dataclass
class ScanView:
    """The fold; :meth:`add` each event with the offset just after its line."""

    start: int = 0
    total: int = 0
    views: dict = field(default_factory=dict)          # index -> {"index", "name", "done", "decoded"}
    files: list = field(default_factory=list)
    exit_code: int | None = None
    paused: bool = False
    error: str | None = None
    lines: list = field(default_factory=list)

    def _view(self, k: int, name: str | None = None) -> dict:
        view = self.views.setdefault(k, {"index": k, "name": view_name(k), "done": False, "decoded": False})
        if name:
            view["name"] = name
        self.total = max(self.total, k + 1)
        return view

    def _file(self, name: str) -> None:
        if name not in self.files:
            self.files.append(name)

    def add(self, event, end: int) -> None:
        current = end > self.start
        if isinstance(event, ev.ScanStarted):
            self.total = event.total
            for k in range(event.total):
                self._view(k)
            taken = [k for k, v in sorted(self.views.items()) if v["done"]]
            if len(taken) != event.done:       # an older session's log, or a view taken again: by the count
                for k, view in sorted(self.views.items()):
                    view["done"] = k < event.done
        elif isinstance(event, ev.ViewAcquired):
            self._view(event.index, event.folder.name)["done"] = True
        elif isinstance(event, (ev.ViewDecoded, ev.ViewPlaced)):
            view = self._view(event.index, event.name)
            view["decoded"] = view["done"] = True
        elif isinstance(event, ev.MeshReady):
            self._file(event.path.name)
        elif isinstance(event, ev.StageFinished) and event.stage == "report":
            self._file(REPORT_FILE)
        elif isinstance(event, ev.Progress):
            self.lines = (self.lines + [event.message])[-KEPT_LINES:]
        elif isinstance(event, ev.JobFailed) and current:
            self.error = str(event.error)
            self.lines = (self.lines + [f"failed: {event.error}"])[-KEPT_LINES:]
        elif isinstance(event, JobPaused) and current:
            self.paused = event.paused
        elif isinstance(event, JobExited) and current:
            self.exit_code, self.paused = event.exit_code, False
            if event.exit_code == 0 and MESH_FILE in self.files:
                self._file(SUMMARY_FILE)       # written last by a processing that finished
            self.lines = (self.lines + list(event.last_lines))[-KEPT_LINES:]

    def snapshot(self) -> dict:
        """``{"views": [...], "files": [...], "paused", "exit_code", "error", "lines"}``."""
        return {"views": [self._view(k) for k in range(self.total)], "files": list(self.files),
                "paused": self.paused, "exit_code": self.exit_code, "error": self.error, "lines": list(self.lines)}
