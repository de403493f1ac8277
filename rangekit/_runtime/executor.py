"""What runs a call: here, on a thread, in a spawned child process; and how many workers run beside each other.

One configured number says how many calls of a kind run at once (decoding views, refining view pairs, reading
frames, rendering a report's panels, a local Dask cluster's processes): :func:`worker_count`. Like kiss-icp's
``max_num_threads: 0  # automatic``, 0 means automatic: the ``RANGEKIT_WORKERS`` environment variable when set to
a whole number >= 1, else the cores this process may run on (``os.sched_getaffinity``). A function that takes
``workers`` takes 0 (automatic) by default and resolves it here; no other module writes a worker count. Every
parallel map in rangekit takes its results in order, so the outputs do not depend on the count (the views'
decoding is per pixel, the pairs' refinements and the joint terms are summed in order): only the time does.

:class:`Where` names the places a call can run; :func:`start` starts a call in one of them behind one interface
(``with start(...) as call: ...; call.result()``); :func:`ordered_map` maps a function over items on worker
threads, yielding the results in order with a bounded look-ahead (a view's image stack is hundreds of MB: at most
``workers`` are held at once).
"""

from __future__ import annotations

import os
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager, nullcontext
from enum import Enum
from itertools import islice
from typing import TYPE_CHECKING, Any, TypeVar

from rangekit.errors import ConfigError

if TYPE_CHECKING:
    from rangekit._runtime.child import ChildCall, ThreadCall

__all__ = ["WORKERS_ENV", "Where", "worker_count", "start", "ordered_map", "thread_pool", "Done"]

#: The environment variable that sets the worker count (0 or unset: automatic).
WORKERS_ENV = "RANGEKIT_WORKERS"

T = TypeVar("T")
R = TypeVar("R")


class Where(str, Enum):
    """Where a call runs (:data:`rangekit.app.runner.PLACEMENTS` says which stage runs where)."""

    HERE = "here"        # on the calling thread, when it is called
    THREAD = "thread"    # on a thread of this process, beside the caller
    CHILD = "child"      # in a spawned child process (library code that holds the GIL: Open3D's Poisson)
    DASK = "dask"        # a task on a Dask cluster (rangekit.app.batch.sessions)


def worker_count(workers: int = 0) -> int:
    """The number of calls of one kind run at once: ``workers`` when >= 1, else (0, automatic) the
    ``RANGEKIT_WORKERS`` environment variable, else the cores this process may run on."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ConfigError(f"workers: expected a whole number >= 0 (0: automatic), found {workers!r}")
    if workers >= 1:
        return workers
    text = os.environ.get(WORKERS_ENV, "").strip()
    if text not in ("", "0"):
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise ConfigError(f"{WORKERS_ENV}: expected a whole number >= 1 (or 0: automatic), found {text!r}")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


class Done:
    """A call already made on the calling thread, behind the interface of :class:`ChildCall`."""

    def __init__(self, fn: Callable, args: tuple, kwargs: dict) -> None:
        self._value, self._error = None, None
        try:
            self._value = fn(*args, **kwargs)
        except Exception as exc:   # raised by result(), as a thread's or a child's error is
            self._error = exc

    def result(self) -> Any:
        if self._error is not None:
            raise self._error
        return self._value

    def __enter__(self) -> "Done":
        return self

    def __exit__(self, *exc) -> None:
        pass


def start(where: Where, fn: Callable, *args, child: ChildCall | None = None, **kwargs) -> ChildCall | ThreadCall | Done:
    """Start ``fn(*args, **kwargs)`` ``where`` (here, on a thread or in a child process, ``child`` when one was
    spawned ahead: :func:`rangekit._runtime.child.spawn_child`); use as ``with start(...) as call: ...;
    call.result()``. A child is a thread in a daemonic process (a Dask worker)."""
    if where is Where.HERE:
        if child is not None:
            child.terminate()
        return Done(fn, args, kwargs)
    if where is Where.DASK:
        raise ConfigError("where: a single call runs here, on a thread or in a child; Dask runs tasks "
                          "(rangekit.app.batch.sessions)")
    from rangekit._runtime.child import call_beside

    return call_beside(fn, *args, in_child=where is Where.CHILD, child=child, **kwargs)


def thread_pool(workers: int = 0, name: str = "rangekit") -> ThreadPoolExecutor:
    """A pool of :func:`worker_count` threads (``with thread_pool() as pool: pool.map(...)``)."""
    return ThreadPoolExecutor(max_workers=worker_count(workers), thread_name_prefix=name)


def ordered_map(fn: Callable[[T], R], items: Iterable[T], *, workers: int = 0, name: str = "rangekit",
                each: Callable[[int], AbstractContextManager] | None = None) -> Iterator[R]:
    """``fn`` of each item, yielded in order, ``workers`` (:func:`worker_count`) items at a time on as many
    threads, the next started as one is taken (at most ``workers`` results held); on one worker, here, one after
    another. ``each(n)``: a context each call runs in, given the number of workers (e.g. numba's threads)."""
    n = worker_count(workers)
    inside = each if each is not None else (lambda _n: nullcontext())

    def one(item: T) -> R:
        with inside(n):
            return fn(item)

    if n <= 1:
        for item in items:
            yield one(item)
        return
    queued = iter(items)
    with ThreadPoolExecutor(max_workers=n, thread_name_prefix=name) as pool:
        running = deque(pool.submit(one, item) for item in islice(queued, n))
        try:
            while running:
                result = running.popleft().result()
                for item in islice(queued, 1):
                    running.append(pool.submit(one, item))
                yield result
                del result   # not held while the next is decoded
        finally:
            for f in running:
                f.cancel()
