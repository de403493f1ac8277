"""The moments an acquisition waits on its devices, told to the work beside it.

While a frame is taken the capture's thread mostly sleeps: the projector's latency after each pattern (0.1 s
on the default rig), the turntable's settling after each move. Work beside it that holds Python's GIL for tens
of milliseconds in one call (Open3D's TSDF integration of a view: 37 ms) would stall the capture if it started
just before the capture wakes, so a frame would be late. :class:`QuietWindows` lets that work start only at the
beginning of such a wait: the capture opens a window for the length of each wait, or until it closes it for a
turntable's move (:meth:`QuietWindows.open`), and closes it when it wakes (:meth:`QuietWindows.close`); :meth:`QuietWindows.wait` returns once a window with
enough time left is open, at once when no acquisition runs (:meth:`QuietWindows.end`), or after a timeout (the
capture is stuck elsewhere: the work goes on rather than waiting for ever).
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager

__all__ = ["QuietWindows", "quiet_window"]


class QuietWindows:
    """Windows in which the capture sleeps (module doc). Thread-safe; inactive until the first :meth:`open`."""

    def __init__(self) -> None:
        self._changed = threading.Condition()
        self._until = 0.0          # time.monotonic() at which the open window closes (0: none open)
        self._active = False       # an acquisition is taking frames
        self._longest = 0.0        # the longest window of known length opened so far, seconds

    def open(self, seconds: float | None = None) -> None:
        """The capture sleeps for ``seconds`` from now, or None: until :meth:`close` (a turntable's move)."""
        with self._changed:
            self._active = True
            if seconds is None:
                self._until = float("inf")
            else:
                self._until = time.monotonic() + float(seconds)
                self._longest = max(self._longest, float(seconds))
            self._changed.notify_all()

    def close(self) -> None:
        """The capture is awake (taking a frame)."""
        with self._changed:
            self._until = 0.0

    def end(self) -> None:
        """The acquisition is over (or failed): nobody waits for a window any more."""
        with self._changed:
            self._until, self._active = 0.0, False
            self._changed.notify_all()

    def wait(self, need_s: float, timeout_s: float = 1.0) -> bool:
        """Block until a window with at least ``need_s`` seconds left is open (True; when the capture's waits are
        all shorter, one opened at most half the longest seen so far ago: a niced thread wakes late), no acquisition runs (True), or
        ``timeout_s`` has passed (False)."""
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while self._active:
                now = time.monotonic()
                if self._until - now >= (min(need_s, 0.5 * self._longest) if self._longest > 0 else need_s):
                    return True
                if now >= deadline:
                    return False
                self._changed.wait(deadline - now)
            return True


@contextmanager
def quiet_window(quiet: QuietWindows | None, seconds: float | None = None):
    """A window of ``quiet`` (None: nothing) open while the block waits on the devices: ``seconds`` long, or None:
    until the block ends (a turntable's move)."""
    if quiet is not None:
        quiet.open(seconds)
    try:
        yield
    finally:
        if quiet is not None:
            quiet.close()
