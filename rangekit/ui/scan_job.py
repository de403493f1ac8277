"""The Scan page's job: ``rangekit scan`` run as a child process into a session folder under ``--sessions``,
watched through the files it writes.

A session started here is an ordinary session: the child is the command line's own ``rangekit scan``, so
``rangekit process`` and ``rangekit scan --resume`` work on it from the shell, and the reverse. Stopping sends
the child Ctrl-C (SIGINT): the views taken are finished and recorded, as at a terminal, and ``resume`` continues
it (``--resume``). Pages come and go without touching it; two pages see the same files. The growing model is read
from the session folder: ``session.json`` (which views are done) and each view's cloud cache (``view_*/cloud.ply``,
written as the view is decoded while the next one is captured), placed by the turntable's prior.
"""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np

from rangekit.errors import RangekitError
from rangekit.ui.paths import confined

__all__ = ["ScanJob", "POINTS_PER_VIEW", "view_points", "option_limits"]


def option_limits() -> dict:
    """The Scan page's form, from the options' own dataclasses (the command line's parser and their checks read the
    same metadata, :mod:`rangekit._runtime.option_fields`): ``{"scan": {field: {"flag", "min", "max", "integer",
    "default", ...}}, "process": {...}}``, each ranged option of :class:`~rangekit.app.scan.options.ScanOptions` and
    :class:`~rangekit.app.process.options.ProcessOptions`, and the processing's ``fusion`` and ``mesh_format`` with
    their ``choices`` and ``default`` (``GET /api/options``)."""
    from rangekit._runtime.option_fields import default_of, limits
    from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
    from rangekit.app.process.options import FUSION_METHODS, ProcessOptions
    from rangekit.app.scan.options import ScanOptions

    process = limits(ProcessOptions)
    for name, choices in (("fusion", FUSION_METHODS), ("mesh_format", MESH_EXPORT_FORMATS)):
        process[name] = {"choices": list(choices), "default": default_of(ProcessOptions, name)}
    return {"scan": limits(ScanOptions), "process": process}

#: The most points of one view sent to a page (every n-th of the view's cloud).
POINTS_PER_VIEW = 20_000


#: Starts ``python -m rangekit ARGS`` so that it gets Ctrl-C (SIGINT) when the app's process ends, however it ends
#: (Linux's parent-death signal, kept across exec): a server killed mid-scan leaves a session that ``--resume``
#: completes, not a scan running on without a window. The child starts with SIGINT blocked (:func:`_spawn`): a
#: stop that comes while Python is still starting waits, pending, until :data:`_RUN` unblocks it inside its
#: ``try``, and ends the child quietly with 130, never a KeyboardInterrupt traceback in the scan's log.
_RUN = ("import runpy, signal, sys\n"
        "try:\n"
        "    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})\n"
        "    runpy.run_module('rangekit', run_name='__main__', alter_sys=True)\n"
        "except KeyboardInterrupt:\n"
        "    sys.exit(130)\n")
_LAUNCH = ("import ctypes, os, signal, sys\n"
           "if sys.platform.startswith('linux'):\n"
           "    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGINT), 0, 0, 0)\n"
           "    if os.getppid() != int(sys.argv[1]):\n"
           "        sys.exit(130)\n"
           "os.execv(sys.executable, [sys.executable, '-c', sys.argv[2], *sys.argv[3:]])\n")


def _child_command() -> list[str]:
    return [sys.executable, "-c", _LAUNCH, str(os.getpid()), _RUN]


class _Spawner:
    """Starts the children from one thread that lives as long as the app: Linux's parent-death signal follows the
    *thread* that started a child, and a thread of Starlette's pool ends when idle, which would stop a scan."""

    def __init__(self) -> None:
        self._jobs: queue.Queue = queue.Queue()
        threading.Thread(target=self._run, name="rangekit-spawner", daemon=True).start()

    def _run(self) -> None:
        while True:
            args, box, done = self._jobs.get()
            try:
                box.append(_spawn(args))
            except Exception as exc:  # noqa: BLE001 - handed to the caller's thread
                box.append(exc)
            done.set()

    def spawn(self, args: list[str]) -> subprocess.Popen:
        box: list = []
        done = threading.Event()
        self._jobs.put((args, box, done))
        done.wait()
        if isinstance(box[0], Exception):
            raise box[0]
        return box[0]


_SPAWNER: _Spawner | None = None
_SPAWNER_LOCK = threading.Lock()


def _spawned(args: list[str]) -> subprocess.Popen:
    """``rangekit ARGS`` started by the app's one spawning thread (:class:`_Spawner`)."""
    global _SPAWNER
    with _SPAWNER_LOCK:
        if _SPAWNER is None:
            _SPAWNER = _Spawner()
    return _SPAWNER.spawn(args)


def _spawn(args: list[str]) -> subprocess.Popen:
    """``rangekit ARGS`` as a child, started with SIGINT blocked (this thread's mask, inherited; see :data:`_RUN`)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        return subprocess.Popen([*_child_command(), *args], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class ScanJob:
    """At most one ``rangekit scan`` child of the app at a time, into ``sessions/<name>``."""

    def __init__(self, sessions: Path, obj: str = "lumpy", holder=None) -> None:
        """``holder``: the app's :class:`rangekit.ui.rig_holder.RigHolder`; on hardware its devices are handed to
        the scan child (closed here, ``--rig RIG.json`` there) and opened again when it ends."""
        self.sessions, self.obj, self.holder = Path(sessions).resolve(), obj, holder
        self._lock = threading.Lock()
        self._proc: subprocess.Popen | None = None
        self.name: str | None = None
        self.log: list[str] = []
        self.exit_code: int | None = None
        self.paused = False

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def start(self, name: str, views: int, *, resume: bool = False) -> dict:
        """Start ``rangekit scan --out sessions/name --views N`` (or ``--resume sessions/name``); refused while a
        scan runs. ``name``: a folder name under the sessions folder (:func:`rangekit.ui.paths.confined`)."""
        folder = confined(self.sessions, name)
        if folder.parent != self.sessions:
            raise RangekitError(f"session {name!r}: a folder name directly under the sessions folder")
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
        return self._launch(folder, ["scan", *args], devices=hardware)

    def process(self, name: str, *, fusion: str = "poisson", mesh_format: str = "ply", report: bool = True) -> dict:
        """Reprocess session ``name`` with other options: ``rangekit process sessions/name --fusion F --format
        FMT [--no-report]`` as a child (refused while a scan or another processing runs)."""
        from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
        from rangekit.app.process.options import FUSION_METHODS

        folder = confined(self.sessions, name)
        if folder.parent != self.sessions or not (folder / "session.json").is_file():
            raise RangekitError(f"session {name!r}: no session folder of that name under the sessions folder")
        if fusion not in FUSION_METHODS:
            raise RangekitError(f"fusion: expected {' or '.join(FUSION_METHODS)}, found {fusion!r}")
        if mesh_format not in MESH_EXPORT_FORMATS:
            raise RangekitError(f"format: expected one of {', '.join(MESH_EXPORT_FORMATS)}, found {mesh_format!r}")
        return self._launch(folder, ["process", str(folder), "--fusion", fusion, "--format", mesh_format,
                                     *([] if report else ["--no-report"])])

    def _launch(self, folder: Path, args: list[str], devices: bool = False) -> dict:
        """Start ``rangekit ARGS``; ``devices``: it opens the rig's hardware, released by the app meanwhile."""
        with self._lock:
            if self.running:
                raise RangekitError(f"a scan is running: {self.name}; stop it first")
            if devices:
                self.holder.release(f"scan {folder.name}")
            self.name, self.log, self.exit_code, self.paused = folder.name, [], None, False
            try:
                self._proc = _spawned(args)
            except OSError:
                if devices:
                    self.holder.reacquire()
                raise
            threading.Thread(target=self._read, args=(self._proc, devices), name="rangekit-scan-log",
                             daemon=True).start()
        return self.snapshot()

    def pause(self, paused: bool) -> dict:
        """Freeze the running scan between two instructions (SIGSTOP) or let it go on (SIGCONT). On the simulator
        it picks up exactly where it was; on hardware the projector keeps its pattern and the turntable its angle
        while paused (a real-time capture re-waits its pattern delay on the next frame)."""
        with self._lock:
            if not self.running:
                raise RangekitError("no scan is running")
            os.kill(self._proc.pid, signal.SIGSTOP if paused else signal.SIGCONT)
            self.paused = bool(paused)
        return self.snapshot()

    def _read(self, proc: subprocess.Popen, devices: bool = False) -> None:
        for line in proc.stdout:
            line = line.rstrip()
            if line:
                self.log = (self.log + [line])[-200:]
        code = proc.wait()
        with self._lock:
            if proc is self._proc:
                self.exit_code = code
        if devices:
            self.holder.reacquire()

    def stop(self) -> dict:
        """Ctrl-C to the running scan: its views taken are finished and recorded; ``resume`` continues it."""
        with self._lock:
            if not self.running:
                raise RangekitError("no scan is running")
            self._proc.send_signal(signal.SIGINT)
            if self.paused:
                self._proc.send_signal(signal.SIGCONT)
                self.paused = False
        return self.snapshot()

    def snapshot(self) -> dict:
        """What a page shows: the session, whether it runs, its exit code, its last lines, its views."""
        # running until its exit code is recorded: the child may have ended while its last lines are still read
        running = self.running or (self._proc is not None and self.exit_code is None)
        out = {"name": self.name, "running": running, "paused": self.paused and self.running,
               "exit_code": self.exit_code, "log": self.log[-30:]}
        if self.name is not None:
            out.update(session_state(self.sessions / self.name))
        return out

    def close(self) -> None:
        """At the app's end: a running scan is stopped as Ctrl-C would stop it (its session resumable)."""
        if self.running:
            self._proc.send_signal(signal.SIGINT)
            self._proc.send_signal(signal.SIGCONT)
            try:
                self._proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self._proc.kill()


def session_state(folder: Path) -> dict:
    """``{"views": [{"index", "name", "done", "decoded"}], "files": [...]}`` of a session folder as it is on disk
    now (an empty list before its session.json exists)."""
    from rangekit.formats.sessions.session import Session

    if not (folder / "session.json").is_file():
        return {"views": [], "files": []}
    try:
        session = Session.load(folder)
    except RangekitError as exc:
        return {"views": [], "files": [], "error": str(exc)}
    views = [{"index": v.index, "name": v.folder.name, "done": v.done,
              "decoded": (v.folder / "cloud.json").is_file()} for v in session.views]
    files = [n for n in ("preview.ply", "mesh.ply", "mesh_watertight.ply", "report.html", "summary.json")
             if (folder / n).is_file()]
    return {"views": views, "files": files}


def view_points(folder: Path, index: int) -> bytes:
    """Float32 (n, 3) bytes, x y z in millimetres, of view ``index``'s decoded cloud placed by the turntable prior
    (the first view's frame), every k-th point so that n <= :data:`POINTS_PER_VIEW`."""
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.sessions.session import Session
    from rangekit.geometry import apply_T
    from rangekit.rig.rig_file import turntable_prior

    session = Session.load(folder)
    if not 0 <= index < len(session.views):
        raise RangekitError(f"view {index}: the session has views 0-{len(session.views) - 1}")
    view = session.views[index]
    if not (view.folder / "cloud.json").is_file():
        raise RangekitError(f"{view.folder.name}: not decoded yet")
    cloud = load_cloud(view.folder / "cloud.ply")
    step = max(1, -(-len(cloud) // POINTS_PER_VIEW))
    points = cloud.points[::step]
    rig = session.rig
    if rig.T_world_table is not None:
        T = turntable_prior(rig.T_world_table, [session.views[0].angle, view.angle])[1]
        points = apply_T(T, points)
    return (np.asarray(points, dtype=np.float32) * 1e3).tobytes()
