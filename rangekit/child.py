"""One call run in a child process, for library code that holds the GIL for seconds.

Open3D's screened Poisson holds the GIL for its whole run (12-14 s at depth 9 on the 12-view scan): a
thread beside it cannot run a line of Python, so the work meant to overlap it (the evaluation, writing the
merged cloud) only waited. :func:`child_call` starts the call in a fresh (spawned, not forked: the parent
has OpenMP and BLAS threads) Python process and returns at once; the parent goes on and collects the
answer with :meth:`ChildCall.result`. :func:`call_beside` chooses a child or a thread (for small work,
whose run is shorter than a child's start: about 1 s of imports) behind the same interface.

- The child ignores Ctrl-C: the parent's ``with`` block ends it on any exception (Ctrl-C included), so
  an interrupted run leaves no process behind and prints no second traceback.
- A child that dies without an answer (killed for memory, a crash in native code) is a
  :class:`rangekit.errors.RangekitError` naming the call and its exit code, not a hang.
- The child's exception is raised again in the parent: a rangekit error as it was, anything else as a
  RuntimeError carrying the child's traceback.
- Arguments and results travel pickled: numpy arrays and frozen dataclasses of them, tens of MB in
  tenths of a second. The function must be importable (module level).
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import traceback
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

from rangekit.errors import RangekitError

__all__ = ["ChildCall", "ThreadCall", "call_beside", "child_call"]


def _run(conn, fn: Callable, args: tuple, kwargs: dict) -> None:
    """The child: run ``fn`` on one BLAS thread, send ``("ok", result)`` or ``("error", exception)``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from rangekit.threads import one_blas_thread

    try:
        with one_blas_thread():
            answer = ("ok", fn(*args, **kwargs))
    except BaseException as exc:      # sent to the parent, which raises it
        answer = ("error", exc if isinstance(exc, RangekitError) else
                  RuntimeError(f"{type(exc).__name__}: {exc}\nin the child process:\n{traceback.format_exc()}"))
    try:
        conn.send(answer)
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        conn.send(("error", RuntimeError(f"the child process's answer cannot be sent back: {exc}")))
    conn.close()


class ChildCall:
    """A call running in a child process (see the module docstring); a context manager that ends the
    child if the block raises."""

    def __init__(self, fn: Callable, args: tuple, kwargs: dict) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._name = f"{fn.__module__}.{fn.__qualname__}"
        self._conn, child_conn = ctx.Pipe(duplex=False)
        self._process = ctx.Process(target=_run, args=(child_conn, fn, args, kwargs), daemon=True,
                                    name=f"rangekit-{fn.__name__}")
        self._process.start()
        child_conn.close()     # the parent's copy: EOF once the child's end closes

    def result(self) -> Any:
        """Wait for the child's answer; return it, or raise its exception."""
        try:
            status, value = self._conn.recv()
        except EOFError:
            self._process.join()
            raise RangekitError(f"{self._name} in a child process ended without an answer (exit code "
                                f"{self._process.exitcode}; a negative code is the signal that ended it, "
                                "-9 often the system out of memory)") from None
        finally:
            self._conn.close()
        self._process.join()
        if status == "error":
            raise value
        return value

    def terminate(self) -> None:
        """End the child if it is still running."""
        if self._process.is_alive():
            self._process.terminate()
        self._process.join()
        self._conn.close()

    def __enter__(self) -> "ChildCall":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.terminate()


def child_call(fn: Callable, *args, **kwargs) -> ChildCall:
    """Start ``fn(*args, **kwargs)`` in a spawned child process and return at once; use as
    ``with child_call(f, x) as call: ...; y = call.result()``."""
    return ChildCall(fn, args, kwargs)


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


def call_beside(fn: Callable, *args, in_child: bool, **kwargs) -> ChildCall | ThreadCall:
    """Start ``fn(*args, **kwargs)`` beside this thread, in a child process (``in_child``: for a call that
    holds the GIL) or on a thread; use as ``with call_beside(f, x, in_child=...) as call: ...``. A daemonic
    process (a Dask worker, a multiprocessing pool's worker) may not start children: there it is a thread."""
    in_child = in_child and not multiprocessing.current_process().daemon
    return ChildCall(fn, args, kwargs) if in_child else ThreadCall(fn, args, kwargs)
