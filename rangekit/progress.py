"""Progress for long work: a tqdm bar with an ETA on a terminal, plain lines everywhere else.

Library functions take ``progress``, a callable ``progress(msg, done=None, total=None)``; any function
of one string also works (the counts are then dropped). :class:`Console` is the command line's, on
standard error (results stay on standard output):

- on a terminal, a step with counts draws a ``tqdm`` bar with the elapsed time and the ETA (one bar at a
  time: a new total, or a count going back, starts a new bar), and a message without counts is printed on
  its own line above the bar;
- otherwise (CI, a pipe, a file) every message without counts is one plain line, and a counted step is a
  line at every step when it has at most :data:`EVERY_STEP_UP_TO` steps (a scan's views: one line each),
  else when its bar starts, ends or crosses a tenth of its total (every step with ``verbose``): no carriage
  returns, no escape codes, so logs read as they were written and a 480-frame scan writes about 11 lines.

The level comes from the ``rangekit`` logger (:data:`LOGGER`; the command line's ``-q`` sets it to
WARNING: no progress at all, ``-v`` to DEBUG: every counted step as a line). :class:`StageTimer` records
the wall time of each named stage for the end-of-run summary.
"""

from __future__ import annotations

import logging
import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator, Protocol, TextIO

__all__ = ["Progress", "Console", "StageTimer", "call_progress", "format_seconds", "LOGGER", "BAR_FORMAT"]

#: The package's logger: the command line's ``-q``/``-v`` set its level; library code logs details at DEBUG.
LOGGER = logging.getLogger("rangekit")

#: The terminal bar: description, percentage, bar, counts, elapsed time and the ETA.
BAR_FORMAT = "{desc} {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} [{elapsed}, ETA {remaining}]"


class Progress(Protocol):
    def __call__(self, msg: str, done: int | None = None, total: int | None = None) -> None: ...


def call_progress(progress: Callable | None, msg: str, done: int | None = None, total: int | None = None) -> None:
    """Report to ``progress`` whether it takes counts or only a message (or is None)."""
    if progress is None:
        return
    if done is None or total is None:
        progress(msg)
        return
    try:
        progress(msg, done, total)
    except TypeError:
        progress(msg)


def format_seconds(s: float) -> str:
    return f"{s:.1f} s" if s < 60 else f"{int(s // 60)} min {s % 60:04.1f} s"


class Console:
    """Progress on ``stream`` (default standard error). ``tty`` None = ask the stream; ``level`` None = the
    level set on :data:`LOGGER` (INFO when none is set): above INFO nothing is shown, at DEBUG every counted
    step of a plain stream is a line. ``width``: the bar's width in characters on a terminal."""

    def __init__(self, stream: TextIO | None = None, *, tty: bool | None = None, width: int = 28,
                 level: int | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        if tty is None:
            isatty = getattr(self.stream, "isatty", None)
            tty = bool(isatty and isatty())
        self.tty = tty
        self.width = width
        self.level = level if level is not None else (LOGGER.level or logging.INFO)
        self._bar = None            # the open tqdm bar (terminal)
        self._total = None          # the current counted step's total and last count
        self._done = -1
        self._tenth = -1            # the last tenth of the total written as a plain line

    def __call__(self, msg: str, done: int | None = None, total: int | None = None) -> None:
        if self.level > logging.INFO:
            return
        if done is None or not total:
            self._line(msg)
        elif self.tty:
            self._draw(msg, done, total)
        else:
            self._plain_step(msg, done, total)

    def _line(self, msg: str) -> None:
        if self._bar is not None:
            self._bar.write(msg, file=self.stream)      # above the bar, which is redrawn
        else:
            self.stream.write(f"{msg}\n")
            self.stream.flush()

    def _new_step(self, done: int, total: int) -> bool:
        new = total != self._total or done < self._done
        self._total, self._done = total, done
        return new

    def _plain_step(self, msg: str, done: int, total: int) -> None:
        if self._new_step(done, total):
            self._tenth = -1
        tenth = 10 * min(done, total) // total
        if (total <= EVERY_STEP_UP_TO or self._tenth < 0 or tenth > self._tenth or done >= total
                or self.level <= logging.DEBUG):
            self._tenth = tenth
            self.stream.write(f"{msg}\n")
            self.stream.flush()

    def _draw(self, msg: str, done: int, total: int) -> None:
        from tqdm import tqdm

        if self._new_step(done, total) or self._bar is None:
            self.close()
            self._total, self._done = total, done
            # explicit sizes: a terminal that reports 0 x 0 (a bare pty) would hide tqdm's bar
            self._bar = tqdm(total=total, initial=min(done, total), desc=msg, file=self.stream,
                             ncols=self.width + 60, nrows=50, bar_format=BAR_FORMAT, mininterval=0.1, leave=True)
        else:
            self._bar.set_description_str(msg, refresh=False)
            self._bar.update(min(done, total) - self._bar.n)
        if done >= total:
            self.close()

    def close(self) -> None:
        """End the open bar (its last state stays on the screen)."""
        if self._bar is not None:
            self._bar.refresh()
            self._bar.close()
            self._bar = None


#: Off a terminal, a counted step of at most this many steps (the views of a scan, its pairs) prints every step:
#: a per-tenth throttle over 12 views printed 11 "decoded view_NNN" lines, which reads as a lost view. Longer
#: ones (a scan's 720 frames, a laser scan's 400 steps) print a line per tenth.
EVERY_STEP_UP_TO = 100


class StageTimer:
    """Wall time per named stage, in the order the stages started (a stage run twice, or inside another,
    adds up)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        self.seconds.setdefault(name, 0.0)   # listed in the order the stages started
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0
