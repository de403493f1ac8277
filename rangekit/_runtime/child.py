"""One call run in a child process, for library code that holds the GIL for seconds.

Open3D's screened Poisson holds the GIL for its whole run (12-14 s at depth 9 on the 12-view scan): a
thread beside it cannot run a line of Python, so the work meant to overlap it (the evaluation, writing the
merged cloud) only waited. :func:`child_call` starts the call in a fresh Python process (``python -c``
with this interpreter: not forked, the parent has OpenMP and BLAS threads; not multiprocessing's spawn,
which runs the caller's main script again in the child: without an ``if __name__ == "__main__"`` guard
that script would process the session a second time) and returns at once; the parent goes on and
collects the answer with :meth:`ChildCall.result`. :func:`call_beside` chooses a child or a thread (for
small work, whose run is shorter than a child's start: about 1 s of imports) behind the same interface.

- The child ignores Ctrl-C: the parent's ``with`` block ends it on any exception (Ctrl-C included), so
  an interrupted run leaves no process behind and prints no second traceback.
- A child that dies without an answer (killed for memory, a crash in native code) is a
  :class:`rangekit.errors.RangekitError` naming the call and its exit code, not a hang.
- The child's exception is raised again in the parent: a rangekit error as it was, anything else as a
  RuntimeError carrying the child's traceback.
- The call travels pickled on the child's standard input (written by a thread, so a slow child never
  blocks the parent), the answer on a private copy of its standard output; the child's own prints go to
  the parent's stderr. Numpy arrays and frozen dataclasses of them, tens of MB, take tenths of a second.
  The function must be importable (module level).
- A child can be started ahead of its call (:func:`spawn_child`, with the modules the call will need
  imported while the parent still works: Open3D alone takes 0.6 s) and given the call later
  (:meth:`ChildCall.start`).
- A call started with ``more=True`` is then sent further objects (:meth:`ChildCall.send`, queued: the caller
  never waits for the child), which it reads with :func:`messages` until the parent's :meth:`ChildCall.result`
  (or :meth:`ChildCall.close_input`) ends them: a scan's blocks volume filled in a child view by view (issue 51,
  :class:`rangekit.app.process.blocks.BlocksAhead`).
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import pickle
import queue
import subprocess
import sys
import threading
import traceback
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Sequence

from rangekit.errors import RangekitError

__all__ = ["ChildCall", "ThreadCall", "call_beside", "child_call", "spawn_child", "messages"]

# The child's first lines: no Ctrl-C, the parent's import path, then serve the call.
_BOOT = ("import pickle, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
         "sys.path[:] = pickle.load(sys.stdin.buffer); import rangekit._runtime.child as c; c._serve()")


def _serve() -> None:
    """The child: import the modules named first on stdin, then read ``(fn, args, kwargs)`` and run it on one
    BLAS thread; write ``("ok", result)`` or ``("error", exception)`` to the original stdout (fd 1 then points
    at stderr for any prints)."""
    answer_fd = os.dup(1)
    os.dup2(2, 1)
    from rangekit._runtime.open3d_viewer import defer_plotly_viewer
    from rangekit._runtime.threads import one_blas_thread

    defer_plotly_viewer()   # Poisson's child imports Open3D: not its plotly viewer (0.2-0.4 CPU-s, 42 MB)

    try:
        for name in pickle.load(sys.stdin.buffer):
            importlib.import_module(name)
        fn, args, kwargs = pickle.load(sys.stdin.buffer)
        with one_blas_thread():
            answer = ("ok", fn(*args, **kwargs))
    except BaseException as exc:      # sent to the parent, which raises it
        answer = ("error", exc if isinstance(exc, RangekitError) else
                  RuntimeError(f"{type(exc).__name__}: {exc}\nin the child process:\n{traceback.format_exc()}"))
    with os.fdopen(answer_fd, "wb") as out:
        try:
            data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            data = pickle.dumps(("error", RuntimeError(f"the child process's answer cannot be sent back: {exc}")))
        out.write(data)


def messages():
    """In a child's call started with ``more=True``: the objects the parent sends (:meth:`ChildCall.send`), in
    order, until it ends them."""
    while True:
        try:
            item = pickle.load(sys.stdin.buffer)
        except EOFError:   # the parent closed its end: no more
            return
        if isinstance(item, str) and item == _END:
            return
        yield item


#: The parent's last message to a call started with ``more=True`` (:func:`messages`).
_END = "rangekit._runtime.child: end of messages"


class ChildCall:
    """A call running in a child process (see the module docstring); a context manager that ends the
    child if the block raises. ``ChildCall(imports)`` starts the child, which imports ``imports`` (module
    names) and waits; :meth:`start` gives it the call."""

    def __init__(self, imports: Sequence[str] = ()) -> None:
        self._name = "a call"
        self._proc = subprocess.Popen([sys.executable, "-c", _BOOT], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self._writer: threading.Thread | None = None
        self._queue: queue.SimpleQueue = queue.SimpleQueue()   # payloads for the writer thread; None: close stdin
        self._open = False                                     # more messages may follow (start's ``more``)
        self._send(pickle.dumps(list(sys.path)) + pickle.dumps(list(imports)), close=False)   # a few hundred bytes

    def start(self, fn: Callable, args: tuple = (), kwargs: dict | None = None, more: bool = False) -> "ChildCall":
        """Send the call ``fn(*args, **kwargs)`` (once); ``more``: further objects follow (:meth:`send`, read
        with :func:`messages`); return self."""
        if self._writer is not None:
            raise RuntimeError(f"{self._name} was already sent to this child process")
        self._name = f"{fn.__module__}.{fn.__qualname__}"
        self._queue.put(pickle.dumps((fn, args, kwargs or {}), protocol=pickle.HIGHEST_PROTOCOL))
        self._open = bool(more)
        if not more:
            self._queue.put(None)
        self._writer = threading.Thread(target=self._write_queued, daemon=True, name=f"rangekit-{fn.__name__}-send")
        self._writer.start()
        return self

    def send(self, item: Any) -> None:
        """Queue ``item`` for the call started with ``more=True`` (:func:`messages`); returns at once."""
        if not self._open:
            raise RuntimeError(f"{self._name} takes no more messages")
        self._queue.put(pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL))

    def close_input(self) -> None:
        """End the messages of a call started with ``more=True`` (:meth:`result` does it too)."""
        if self._open:
            self._open = False
            self._queue.put(pickle.dumps(_END))
            self._queue.put(None)

    def _write_queued(self) -> None:
        while (payload := self._queue.get()) is not None:
            self._send(payload, close=False)
        self._send(b"")

    def _send(self, payload: bytes, close: bool = True) -> None:
        try:
            self._proc.stdin.write(payload)
            self._proc.stdin.flush()
            if close:
                self._proc.stdin.close()
        except (BrokenPipeError, ValueError):   # the child died or was ended: result() says so
            pass

    def result(self) -> Any:
        """Wait for the child's answer; return it, or raise its exception."""
        self.close_input()
        try:   # unpickled as it arrives: the answer's bytes (66 MB for Poisson's two meshes) are never held whole
            status, value = pickle.load(self._proc.stdout)
        except (EOFError, pickle.UnpicklingError):
            status = None
        code = self._proc.wait()
        if self._writer is not None:
            self._writer.join()
        if status is None:
            raise RangekitError(f"{self._name} in a child process ended without an answer (exit code {code}; a "
                                "negative code is the signal that ended it, -9 often the system out of memory)")
        if status == "error":
            raise value
        return value

    def terminate(self) -> None:
        """End the child if it is still running."""
        if self._proc.poll() is None:
            self._proc.terminate()
        self._proc.wait()
        if self._writer is not None:
            self._queue.put(None)   # a writer waiting for more messages: let it end
            self._writer.join()
        self._proc.stdout.close()

    def __enter__(self) -> "ChildCall":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.terminate()


class ThreadCall:
    """The same interface as :class:`ChildCall` for a call on a thread of this process (its ``with``
    block waits for the call on exit: a thread cannot be ended)."""

    def __init__(self, fn: Callable, args: tuple, kwargs: dict) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"rangekit-{fn.__name__}")
        self._future = self._pool.submit(fn, *args, **kwargs)

    def result(self) -> Any:
        """Wait for the call; return its value or raise its exception."""
        return self._future.result()

    def __enter__(self) -> "ThreadCall":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._pool.shutdown(wait=True)


def call_beside(fn: Callable, *args, in_child: bool, child: ChildCall | None = None,
                **kwargs) -> ChildCall | ThreadCall:
    """Start ``fn(*args, **kwargs)`` beside this thread, in a child process (``in_child``: for a call that
    holds the GIL; in ``child`` when one was spawned ahead, :func:`spawn_child`) or on a thread; use as
    ``with call_beside(f, x, in_child=...) as call: ...``. In a daemonic process (a Dask worker: the unit of
    parallelism there, one per core) it is a thread. A ``child`` not used is ended."""
    in_child = in_child and not multiprocessing.current_process().daemon
    if not in_child:
        if child is not None:
            child.terminate()
        return ThreadCall(fn, args, kwargs)
    return (child or ChildCall()).start(fn, args, kwargs)


def spawn_child(imports: Sequence[str] = ()) -> ChildCall | None:
    """A child process started now, importing ``imports`` while this process goes on, for a later
    :func:`call_beside`; None in a daemonic process (where calls run on threads)."""
    if multiprocessing.current_process().daemon:
        return None
    return ChildCall(imports)


def child_call(fn: Callable, *args, **kwargs) -> ChildCall:
    """Start ``fn(*args, **kwargs)`` in a child process and return at once; use as
    ``with child_call(f, x) as call: ...; y = call.result()``."""
    return ChildCall().start(fn, args, kwargs)
