"""A worker thread that takes items from a queue, one after another, at a lower priority than its caller, and
holds back while told to.

The scan's live processing (the STREAMING placement, :class:`rangekit.app.runner.StreamingWorker`) is one: the
capture's threads come first, so the worker runs at niceness ``nice`` (Linux schedules threads: the kernel gives
the capture the cores whenever it needs them, the worker what they leave), and while the capture is behind it
starts no new item (:meth:`QueueWorker.hold`, :meth:`QueueWorker.release`). Items are handled in the order
given; :meth:`QueueWorker.finish` ends the thread after the item being handled and handles what is left on the
caller's own thread, at the caller's priority (once the capture is over the work is what the caller waits for: a
thread cannot take back the priority it gave away without privilege, and at niceness 10 beside other programs
it got almost no CPU, issue 51); :meth:`QueueWorker.hand_over` says so ahead, as soon as the caller knows the items
to come are its own (the scan's last view: no item starts on the worker from then on, and :meth:`QueueWorker.finish`
finds them all queued); :meth:`QueueWorker.stop` ends it after the item being handled. The first exception of
``fn`` ends the worker and is kept in :attr:`QueueWorker.error` (the caller decides what it means); the caller's
thread never sees it raised.
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from typing import Any

__all__ = ["QueueWorker"]

_END = object()   # the last item: the worker ends when it takes it


class QueueWorker:
    """``fn(item)`` for each :meth:`put` item, in order, on a thread of its own named ``name`` at niceness
    ``nice`` (module doc); started at once. ``context()``: a context the worker's whole loop runs in, and the items
    :meth:`finish` hands on to the caller, entered there before the worker ends (the scan's:
    :func:`rangekit._runtime.memory.reuse_freed_memory`, one block from the first view to the last). ``idle()``:
    called on the worker before it waits for the next item, returns how long to wait before calling it again (None:
    until an item comes): work done ahead while the queue is empty (the scan's last view's frames read as they are
    written), never while held. :attr:`paused` counts the items that waited for a :meth:`release`,
    :attr:`error` holds the exception that ended it (None: none)."""

    def __init__(self, fn: Callable[[Any], None], *, name: str, nice: int = 0,
                 context: Callable[[], AbstractContextManager] = nullcontext,
                 idle: Callable[[], float | None] | None = None) -> None:
        self._fn, self._nice, self._context, self._idle = fn, nice, context, idle
        self._queue: queue.Queue = queue.Queue()
        self._go = threading.Event()     # cleared while held
        self._go.set()
        self._stopping = self._handing_over = False
        self._handed: list = []          # the item the worker took when told to hand over (finish)
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

    def hand_over(self) -> None:
        """From now on no item starts on the worker (nor its idle work): the item it is handling goes on, those
        queued and to come wait for :meth:`finish`, which handles them on the caller's thread, in order. The worker
        stays in its context until then (module doc)."""
        self._handing_over = True

    def finish(self) -> None:
        """Handle every item queued (no more holding back): the worker ends after the item it is handling, the rest
        are handled here, on the caller's thread and priority (module doc), unless an item failed. Returns when all
        are done."""
        with self._context():   # entered before the worker's ends: one block from its items on to the caller's
            self._handing_over = True
            self._go.set()
            self._queue.put(_END)
            self._thread.join()
            left = self._handed
            while True:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
                if item is not _END:
                    left.append(item)
            for item in left:
                if self.error is not None:
                    return
                self._call(item)

    def stop(self) -> None:
        """End the thread after the item being handled; the queued ones are dropped. Returns when it has ended."""
        self._stopping = True
        self._go.set()
        self._queue.put(_END)
        self._thread.join()

    def _run(self) -> None:
        _lower_priority(self._nice)
        with self._context():
            self._loop()

    def _loop(self) -> None:
        while self.error is None:
            try:
                item = self._queue.get(timeout=self._idle_call())
            except queue.Empty:
                continue
            if item is _END or self._stopping:
                return
            if not self._handing_over and not self._go.is_set():   # held: wait for the release
                self.paused += 1
                self._go.wait()
                if self._stopping:
                    return
            if self._handing_over:      # hand_over(), finish(): the caller handles this item and the rest, in order
                self._handed.append(item)
                continue                # until finish()'s end (its context entered by then)
            self._call(item)

    def _idle_call(self) -> float | None:
        """``idle()`` before the worker waits for an item (not while held, nor once told to end): how long to wait
        before calling it again (None: until an item comes). Its exception is dropped: idle work is optional."""
        if self._idle is None or not self._go.is_set() or self._handing_over or self._stopping:
            return None
        try:
            return self._idle()
        except Exception:   # noqa: BLE001 - idle work only does ahead what an item would do (class doc)
            return None

    def _call(self, item: Any) -> None:
        """``fn(item)``, its exception kept in :attr:`error` (module doc)."""
        try:
            self._fn(item)
        except BaseException as exc:   # noqa: BLE001 - kept for the caller (module doc)
            self.error = exc


def _lower_priority(nice: int) -> None:
    """This thread at niceness ``nice`` (Linux schedules threads; elsewhere, or with 0, nothing)."""
    if nice <= 0:
        return
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    except (AttributeError, OSError):
        pass
