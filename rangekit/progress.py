"""Progress for long work: a bar on a terminal, plain lines everywhere else.

Library functions take ``progress``, a callable ``progress(msg, done=None, total=None)``; any function
of one string also works (the counts are then dropped). :class:`Console` is the command line's:

- on a terminal, a step with counts redraws one bar line in place (carriage return), and a message
  without counts is printed on its own line;
- otherwise (CI, a pipe, a file) every call prints one plain line: no carriage returns, no escape
  codes, so logs read as they were written.

:class:`StageTimer` records the wall time of each named stage for the end-of-run summary.
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager
from typing import Callable, Iterator, Protocol, TextIO

__all__ = ["Progress", "Console", "StageTimer", "call_progress", "format_seconds"]


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
    """Progress on ``stream`` (default stdout). ``tty`` None = ask the stream."""

    def __init__(self, stream: TextIO | None = None, *, tty: bool | None = None, width: int = 28) -> None:
        self.stream = stream if stream is not None else sys.stdout
        if tty is None:
            isatty = getattr(self.stream, "isatty", None)
            tty = bool(isatty and isatty())
        self.tty = tty
        self.width = width
        self._bar_open = False   # a bar line is drawn and not yet ended

    def __call__(self, msg: str, done: int | None = None, total: int | None = None) -> None:
        if not self.tty or done is None or not total:
            self._end_bar()
            self.stream.write(f"{msg}\n")
        else:
            filled = int(round(self.width * min(done, total) / total))
            bar = "#" * filled + "-" * (self.width - filled)
            self.stream.write(f"\r[{bar}] {done}/{total} {msg}\x1b[K")
            self._bar_open = done < total
            if not self._bar_open:
                self.stream.write("\n")
        self.stream.flush()

    def _end_bar(self) -> None:
        if self._bar_open:
            self.stream.write("\n")
            self._bar_open = False


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
