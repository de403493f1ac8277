"""A worker thread that takes items from a queue, one after another, at a lower priority than its caller, and
holds back while told to.

The scan's live processing (the STREAMING placement, :class:`rangekit.app.runner.StreamingWorker`) is one: the
capture's threads come first, so the worker runs at niceness ``nice`` (Linux schedules threads: the kernel gives
the capture the cores whenever it needs them, the worker what they leave), and while the capture is behind it
starts no new item (:meth:`QueueWorker.hold`, :meth:`QueueWorker.release`). Items are handled in the order
given; :meth:`QueueWorker.finish` handles what is queued, then ends the thread; :meth:`QueueWorker.stop` ends it
after the item being handled. The first exception of ``fn`` ends the worker and is kept in
:attr:`QueueWorker.error` (the caller decides what it means); the caller's thread never sees it raised.
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["QueueWorker"]

_END = object()   # the last item: the worker ends when it takes it


class QueueWorker:
    """``fn(item)`` for each :meth:`put` item, in order, on a thread of its own named ``name`` at niceness
    ``nice`` (module doc); started at once. :attr:`paused` counts the items that waited for a :meth:`release`,
    :attr:`error` holds the exception that ended it (None: none)."""

    def __init__(self, fn: Callable[[Any], None], *, name: str, nice: int = 0) -> None:
        self._fn, self._nice = fn, nice
        self._queue: queue.Queue = queue.Queue()
        self._go = threading.Event()     # cleared while held
        self._go.set()
        self._stopping = False
        self.paused = 0
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def put(self, item: Any) -> None:
        """Queue ``item`` (handled after those before it)."""
        self._queue.put(item)

    def hold(self) -> None:
        """Start no new item until :meth:`release` (the item being handled goes on)."""
        self._go.clear()

    def release(self) -> None:
        """Let items start again (after :meth:`hold`)."""
        self._go.set()

    def finish(self) -> None:
        """Handle every item queued (no more holding back), then end the thread; returns when it has ended."""
        self._go.set()
        self._queue.put(_END)
        self._thread.join()

    def stop(self) -> None:
        """End the thread after the item being handled; the queued ones are dropped. Returns when it has ended."""
        self._stopping = True
        self._go.set()
        self._queue.put(_END)
        self._thread.join()

    def _run(self) -> None:
        _lower_priority(self._nice)
        try:
            while True:
                item = self._queue.get()
                if item is _END or self._stopping:
                    return
                if not self._go.is_set():   # held: wait for the release
                    self.paused += 1
                    self._go.wait()
                    if self._stopping:
                        return
                self._fn(item)
        except BaseException as exc:   # kept for the caller (module doc)
            self.error = exc


def _lower_priority(nice: int) -> None:
    """This thread at niceness ``nice`` (Linux schedules threads; elsewhere, or with 0, nothing)."""
    if nice <= 0:
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    except (AttributeError, OSError):
        pass
