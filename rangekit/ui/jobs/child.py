"""The web app's children: ``python -m rangekit ARGS`` started so that it gets Ctrl-C when the app ends, from one
thread that lives as long as the app (:func:`spawned`); its output merged into one pipe, for people."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading

__all__ = ["spawned"]


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


def spawned(args: list[str]) -> subprocess.Popen:
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
