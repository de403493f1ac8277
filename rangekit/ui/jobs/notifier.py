"""The app's one in-process notifier: every job (check, calibration, recorded calibration, registration) and the rig
say here that they changed, from whatever thread they run on; ``/ws/jobs`` (:mod:`rangekit.ui.routes.jobs`) waits on
it in the event loop and sends each page the new state. Nothing is polled: a change wakes the waiting sockets.

A change is a :class:`Changed` event: its :class:`Topic` and the app's version counter when it happened. The
notifier keeps only each topic's last version, not a queue: a page is sent the topic's state as it is when it is
sent (the job's snapshot), so changes that come faster than a page reads them fold into one message and none is
lost. A page that connects (or reconnects) is sent every topic's state first.
"""

from __future__ import annotations

import asyncio
import threading
from dataclasses import dataclass
from enum import Enum

__all__ = ["Changed", "Notifier", "Topic"]


class Topic(str, Enum):
    """What changed; its value is the name a page reads (``{"job": "check", ...}``, ``{"rig": ...}``)."""

    CHECK = "check"
    CALIBRATE = "calibrate"
    RECORDED = "recorded"
    REGISTER = "register"
    RIG = "rig"


@dataclass(frozen=True)
class Changed:
    """``topic`` changed; ``version``: the notifier's count of changes when it did."""

    topic: Topic
    version: int


class Notifier:
    """Each topic's last change and a version counter; :meth:`changed` from any thread, :meth:`wait` in an asyncio
    loop (any number of them), :meth:`since` to read what changed after a version."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._version = 0
        self._last: dict[Topic, int] = {}
        self._waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future]] = []

    @property
    def version(self) -> int:
        """The count of changes so far (0: none yet)."""
        with self._lock:
            return self._version

    def changed(self, topic: Topic) -> None:
        """``topic`` changed: wake every waiter (returns at once; safe from any thread, under the caller's locks)."""
        with self._lock:
            self._version += 1
            self._last[Topic(topic)] = self._version
            waiters, self._waiters = self._waiters, []
        for loop, future in waiters:
            try:
                loop.call_soon_threadsafe(_wake, future)
            except RuntimeError:       # that loop is closed (the app stopping): nobody waits there any more
                pass

    def since(self, version: int) -> tuple[int, list[Changed]]:
        """(the version now, the topics changed after ``version`` as :class:`Changed`, oldest first)."""
        with self._lock:
            changes = sorted((Changed(t, v) for t, v in self._last.items() if v > version), key=lambda c: c.version)
            return self._version, changes

    async def wait(self, version: int) -> None:
        """Return once the version is past ``version`` (at once when it is already)."""
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        entry = (loop, future)
        with self._lock:
            if self._version > version:
                return
            self._waiters.append(entry)
        try:
            await future
        finally:
            with self._lock:
                if entry in self._waiters:
                    self._waiters.remove(entry)


def _wake(future: asyncio.Future) -> None:
    if not future.done():
        future.set_result(None)
