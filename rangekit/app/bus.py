"""A job's event bus: every event published from any thread (the capture's, the frame writer's, the streaming
processor's, the job's) handed to the subscribers on one thread of the bus's own, one at a time, in the order
published. A slow subscriber (a console, a web page, ``events.jsonl``) delays only the others, never the capture.

A subscriber that raises stops the job with its exception: the bus keeps the first one and raises it in the next
:meth:`EventBus.publish` (and from :meth:`EventBus.close`), no later event is handed on; nothing is swallowed.

Each event is stamped with the moment it was published (``time.monotonic()``, on the publishing thread): a
subscriber reads it with :func:`published_at` while the event is handed to it (the session's ``events.jsonl``
gives each line its time so, not when the bus's thread got to it).
"""

from __future__ import annotations

import queue
import threading
import time
from typing import Callable

__all__ = ["EventBus", "published_at"]

_STOP = object()
_handing = threading.local()   # on a bus's thread: .at, the publishing moment of the event being handed on


def published_at() -> float | None:
    """The ``time.monotonic()`` at which the event being handed on was published, when called by a subscriber on
    a bus's thread; None elsewhere (the caller then takes the time itself)."""
    return getattr(_handing, "at", None)


class EventBus:
    """``EventBus(*subscribers)``: a callable subscriber itself (:meth:`publish`), so a job passes it where an
    ``on_event`` goes; :meth:`subscribe` adds one more (a log file's writer, a web socket's feed). Use as ``with
    EventBus(...) as bus:``: leaving it hands on every event published, then ends the thread."""

    def __init__(self, *subscribers: Callable | None) -> None:
        self._subscribers: list[Callable] = [s for s in subscribers if s is not None]
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def subscribe(self, subscriber: Callable | None, *, first: bool = False) -> None:
        """Add ``subscriber``: given the events published from now on, after the earlier subscribers (``first``:
        before them). Call it before the job publishes from several threads."""
        if subscriber is not None:
            if first:
                self._subscribers.insert(0, subscriber)
            else:
                self._subscribers.append(subscriber)

    def unsubscribe(self, subscriber: Callable) -> None:
        """Give ``subscriber`` no more events (those published before still reach it)."""
        self.flush()
        self._subscribers.remove(subscriber)

    @property
    def subscribers(self) -> tuple[Callable, ...]:
        """The subscribers, in the order they are given each event."""
        return tuple(self._subscribers)

    @property
    def quiet(self) -> bool:
        """No subscriber: publishing is a no-op."""
        return not self._subscribers

    def publish(self, event) -> None:
        """Queue ``event`` for the subscribers (returns at once); raise a subscriber's earlier error."""
        if self._error is not None:
            raise self._error
        if not self._subscribers:
            return
        if self._thread is None:
            with self._lock:
                if self._thread is None:
                    self._thread = threading.Thread(target=self._run, name="rangekit-events", daemon=True)
                    self._thread.start()
        self._queue.put((event, time.monotonic()))

    __call__ = publish

    def flush(self) -> None:
        """Wait until every event published so far was handed on; raise a subscriber's error."""
        if self._thread is not None and self._thread.is_alive():
            done = threading.Event()
            self._queue.put((done, None))
            while not done.wait(0.05):
                if not self._thread.is_alive():
                    break
        if self._error is not None:
            raise self._error

    def close(self) -> None:
        """Hand on every event published, end the thread; raise a subscriber's error."""
        if self._thread is not None:
            self._queue.put((_STOP, None))
            self._thread.join()
            self._thread = None
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        while True:
            event, _handing.at = self._queue.get()
            if event is _STOP:
                return
            if isinstance(event, threading.Event):
                event.set()
                continue
            if self._error is not None:
                continue
            try:
                for subscriber in self._subscribers:
                    subscriber(event)
            except BaseException as exc:   # raised on the job's side (module doc)
                self._error = exc

    def __enter__(self) -> "EventBus":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        try:
            self.close()
        except BaseException:   # the job's own error goes on; the subscriber's is secondary
            pass
