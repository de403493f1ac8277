"""The Scan page's job: ``rangekit scan`` (or ``rangekit process``) run as a child process into a session folder
under ``--sessions``, followed through its events (the session's ``events.jsonl``, :mod:`rangekit.app.event_log`).

A session started here is an ordinary session: the child is the command line's own ``rangekit scan``, so
``rangekit process`` and ``rangekit scan --resume`` work on it from the shell, and the reverse. Stopping sends
the child Ctrl-C (SIGINT): the views taken are finished and recorded, as at a terminal, and ``resume`` continues
it (``--resume``). Pages come and go without touching it; every page follows the same file (``/ws/events``). The
app appends its own events to that file: :class:`JobLaunched` before a resumed scan or a processing,
:class:`JobPaused` as it freezes and lets go of the child, :class:`JobExited` with the exit code when it ends. The
child's output is kept for people (its last lines, and a failed child's in :class:`JobExited`), never read for
its state.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
from dataclasses import dataclass, replace
from pathlib import Path

from rangekit.app.event_log import JobExited, JobLaunched, JobPaused, append_event, read_events, to_json
from rangekit.errors import RangekitError
from rangekit.ui.jobs.base import Job, JobState
from rangekit.ui.jobs.child import spawned
from rangekit.ui.jobs.scan_view import ScanView
from rangekit.ui.paths import confined
from rangekit.ui.scan_options import option_limits
from rangekit.formats.sessions.files import EVENTS_FILE, SESSION_FILE

__all__ = ["Followed", "ScanJob"]

#: The child's output lines kept for people.
KEPT_LOG = 200


@dataclass(frozen=True)
class Followed:
    """The events file of the job launched last: ``launch`` counts the launches, ``start`` the file's size
    when this one started (its own events come after); ``exited``: its :class:`JobExited` as a JSON object when
    it ended with no folder to hold its events (a new scan refused before it made its folder)."""

    launch: int
    name: str | None
    path: Path | None
    start: int
    exited: dict | None = None


class ScanJob(Job):
    """At most one ``rangekit scan`` (or ``process``) child of the app at a time, into ``sessions/<name>``."""

    WHAT = "scan"

    def __init__(self, sessions: Path, obj: str = "lumpy", holder=None) -> None:
        """``holder``: the app's :class:`rangekit.ui.rig_holder.RigHolder`; on hardware its devices are handed to
        the scan child (closed here, ``--rig RIG.json`` there) and opened again when it ends."""
        super().__init__()
        self.sessions, self.obj, self.holder = Path(sessions).resolve(), obj, holder
        self._proc: subprocess.Popen | None = None
        self.name: str | None = None
        self.log: list[str] = []
        self.followed = Followed(0, None, None, 0)
        self._view, self._read_to, self._paused = ScanView(), 0, False

    def start(self, name: str, views: int, *, resume: bool = False) -> dict:
        """Start ``rangekit scan --out sessions/name --views N`` (or ``--resume sessions/name``); refused while a
        scan runs. ``name``: a folder name under the sessions folder (:func:`rangekit.ui.paths.confined`)."""
        folder = confined(self.sessions, name)
        if folder.parent != self.sessions:
            raise RangekitError(f"name: {name!r}: a folder name directly under the sessions folder")
        hardware = self.holder is not None and not self.holder.simulated_rig
        if resume:
            args = ["--resume", str(folder)] + ([] if hardware else ["--realtime"])
        else:
            if folder.exists():
                raise RangekitError(f"name: {name} exists under the sessions folder; choose another name (or resume "
                                    "it from the sessions list)")
            lo, hi = (option_limits()["scan"]["views"][k] for k in ("min", "max"))   # rangekit scan's --views
            if isinstance(views, bool) or not isinstance(views, int) or not lo <= views <= hi:
                raise RangekitError(f"views: expected a whole number {lo}-{hi}, found {views!r}")
            # The simulated rig keeps real time, as the hardware would (the rig file's pattern delay,
            # exposure, the turntable's speed): each view decoded while the next is captured.
            args = ["--out", str(folder), "--views", str(views)] + (
                ["--rig", str(self.holder.rig_file)] if hardware else ["--object", self.obj, "--realtime"])
        return self._launch(folder, ["scan", *args], "resume" if resume else "scan", devices=hardware)

    def process(self, name: str, *, fusion: str = "poisson", mesh_format: str = "ply", report: bool = True) -> dict:
        """Reprocess session ``name`` with other options: ``rangekit process sessions/name --fusion F --format
        FMT [--no-report]`` as a child (refused while a scan or another processing runs)."""
        from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
        from rangekit.app.process.options import FUSION_METHODS

        folder = confined(self.sessions, name)
        if folder.parent != self.sessions or not (folder / SESSION_FILE).is_file():
            raise RangekitError(f"session {name!r}: no session folder of that name under the sessions folder")
        if fusion not in FUSION_METHODS:
            raise RangekitError(f"fusion: expected {' or '.join(FUSION_METHODS)}, found {fusion!r}")
        if mesh_format not in MESH_EXPORT_FORMATS:
            raise RangekitError(f"format: expected one of {', '.join(MESH_EXPORT_FORMATS)}, found {mesh_format!r}")
        return self._launch(folder, ["process", str(folder), "--fusion", fusion, "--format", mesh_format,
                                     *([] if report else ["--no-report"])], "process")

    def _launch(self, folder: Path, args: list[str], command: str, devices: bool = False) -> dict:
        """Start ``rangekit ARGS``; ``devices``: it opens the rig's hardware, released by the app meanwhile. The
        events file's end now is where this launch's events begin (:class:`Followed`)."""
        with self._cond:
            if self.running:
                raise RangekitError(f"a scan is running: {self.name}; stop it first")
            path = folder / EVENTS_FILE
            start = path.stat().st_size if path.is_file() else 0
            if folder.is_dir():
                append_event(folder, JobLaunched(command))
            if devices:
                self.holder.release(f"scan {folder.name}")
            try:
                proc = spawned(args)
            except OSError:
                if devices:
                    self.holder.reacquire()
                raise
            self._proc, self.name, self.log = proc, folder.name, []
            self.state, self.fields = JobState.RUNNING, {}
            self.followed = Followed(self.followed.launch + 1, folder.name, path, start)
            self._view, self._read_to, self._paused = ScanView(start=start), 0, False
            threading.Thread(target=self._watch, args=(proc, folder, devices), name="rangekit-scan-child",
                             daemon=True).start()
        return self.snapshot()

    def pause(self, paused: bool) -> dict:
        """Freeze the running scan between two instructions (SIGSTOP) or let it go on (SIGCONT). On the simulator
        it picks up exactly where it was; on hardware the projector keeps its pattern and the turntable its angle
        while paused (a real-time capture re-waits its pattern delay on the next frame)."""
        with self._cond:
            if not self._alive():
                raise RangekitError("no scan is running")
            if paused:
                os.kill(self._proc.pid, signal.SIGSTOP)
            self._say_paused(bool(paused))
            if not paused:
                os.kill(self._proc.pid, signal.SIGCONT)
        return self.snapshot()

    def _say_paused(self, paused: bool) -> None:
        """The pause among the events (once the child made its folder: a page that opens later reads it)."""
        self._paused = paused
        folder = self.sessions / self.name
        if folder.is_dir():
            append_event(folder, JobPaused(paused))

    def _alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def _watch(self, proc: subprocess.Popen, folder: Path, devices: bool = False) -> None:
        """The child's output kept for people; at its end, :class:`JobExited` appended to its events."""
        for line in proc.stdout:
            line = line.rstrip()
            if line:
                self.log = (self.log + [line])[-KEPT_LOG:]
        code = proc.wait()
        exited = JobExited(code, () if code in (0, 130) else tuple(self.log[-8:]))
        if folder.is_dir():
            append_event(folder, exited)
        else:                      # no file to say it in: the events socket says it with the job
            with self._cond:
                if proc is self._proc:
                    self.followed = replace(self.followed, exited=to_json(exited))
        if devices:
            self.holder.reacquire()
        with self._cond:
            if proc is self._proc:
                self._paused = False
                self.finish(JobState.DONE if code == 0 else JobState.CANCELLED if code == 130 else JobState.FAILED,
                            exit_code=code)

    def stop(self) -> dict:
        """Ctrl-C to the running scan: its views taken are finished and recorded; ``resume`` continues it."""
        with self._cond:
            if not self._alive():
                raise RangekitError("no scan is running")
            self._proc.send_signal(signal.SIGINT)
            if self._paused:
                self._say_paused(False)
                self._proc.send_signal(signal.SIGCONT)
        return self.snapshot()

    def _fold(self) -> None:
        """The followed file's new events into the fold (:class:`ScanView`)."""
        path = self.followed.path
        if path is None:
            return
        for event, end in read_events(path, self._read_to):
            self._view.add(event, end)
            self._read_to = end

    def snapshot(self) -> dict:
        """What ``GET /api/scan`` shows: the session, whether it runs (until its exit is among its events),
        paused, its exit code, its views and files (all from its events), the child's last lines."""
        with self._cond:
            self._fold()
            view = self._view.snapshot()
            running = self.running       # until its exit is among its events (:meth:`_watch`)
            code = view["exit_code"] if view["exit_code"] is not None else self.fields.get("exit_code")
            return {"name": self.name, "running": running, "paused": self._paused and running,
                    "exit_code": code, "log": self.log[-30:], "views": view["views"],
                    "files": view["files"], "lines": view["lines"], "error": view["error"],
                    "state": self.state.value}

    def close(self) -> None:
        """At the app's end: a running scan is stopped as Ctrl-C would stop it (its session resumable)."""
        if self._alive():
            self._proc.send_signal(signal.SIGINT)
            self._proc.send_signal(signal.SIGCONT)
            try:
                self._proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self._proc.kill()
