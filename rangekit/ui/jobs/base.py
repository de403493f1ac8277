"""What every job of the web app shares (the check, the calibration, the recorded calibration, the registration,
the scan): one at a time, its :class:`JobState`, its lines for people, the same state for every page open, and a
failure as one line. Each change (a run begun, a line, its end) is said on the app's
:class:`rangekit.ui.jobs.notifier.Notifier` under the job's :attr:`Job.TOPIC`: the pages follow it over
``/ws/jobs``, never by asking again.

A :class:`rangekit.errors.RangekitError` is rangekit's own one-line message, shown as it is (the command line's
words). Anything else is a bug: its traceback goes to the server's log and the page gets one line naming it, never
the traceback.
"""

from __future__ import annotations

import threading
from enum import Enum

from rangekit._runtime.memory import forget_caches
from rangekit.errors import RangekitError
from rangekit.progress import LOGGER

__all__ = ["Job", "JobState", "failed"]


class JobState(str, Enum):
    """Where a job is; its value is what a page reads in ``"state"``."""

    IDLE = "idle"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"

    @property
    def over(self) -> bool:
        """Not running: a new run may start."""
        return self is not JobState.RUNNING


def failed(exc: BaseException, what: str) -> str:
    """The one line a page shows for a job ``what`` ("check", "calibration"...) that raised ``exc``."""
    if isinstance(exc, RangekitError):
        return str(exc)
    LOGGER.error("%s failed", what, exc_info=exc)
    return f"the {what} failed: {type(exc).__name__}: {exc}"


class Job:
    """One job of its kind at a time: ``state`` (:class:`JobState`), ``fields`` (what the page shows of the run:
    its result, its error), ``lines`` (its progress, the last :attr:`KEPT_LINES`). A subclass names itself
    (:attr:`WHAT`), its lines' key (:attr:`LINES`) and its :attr:`TOPIC` on ``notifier`` (a
    :class:`rangekit.ui.jobs.notifier.Notifier`; None: it tells nobody), and runs its work with :meth:`launch`."""

    WHAT = "job"
    LINES = "lines"
    KEPT_LINES = 200
    SHOWN_LINES = 40
    TOPIC = None

    def __init__(self, notifier=None) -> None:
        self._cond = threading.Condition()
        self.notifier = notifier
        self.state = JobState.IDLE
        self.fields: dict = {}
        self.lines: list[str] = []

    def changed(self) -> None:
        """Say that the snapshot changed (the pages following the job are sent it again)."""
        if self.notifier is not None and self.TOPIC is not None:
            self.notifier.changed(self.TOPIC)

    @property
    def running(self) -> bool:
        return not self.state.over

    def snapshot(self) -> dict:
        """What a page shows: ``{"state": ..., its fields..., LINES: [...]}``."""
        with self._cond:
            return {"state": self.state.value, **self.fields, self.LINES: list(self.lines[-self.SHOWN_LINES:])}

    def say(self, line, *args, **kwargs) -> None:
        """A line for people (the ``progress(msg, done, total)`` and ``report(line)`` callables of the library)."""
        with self._cond:
            self.lines = (self.lines + [str(line)])[-self.KEPT_LINES:]
        self.changed()

    def begin(self, **fields) -> None:
        """Mark a run started (refused while one runs), with ``fields`` shown from now on."""
        with self._cond:
            if self.running:
                raise RangekitError(f"a {self.WHAT} is running already")
            self.state, self.fields, self.lines = JobState.RUNNING, dict(fields), []
        self.changed()

    def finish(self, state: JobState, **fields) -> None:
        """The run ended in ``state``; ``fields`` replace what it showed (a failure's ``error``). The memory the
        run took is handed back (:func:`forget_caches`): a server left running keeps no job's rays, textures
        or freed heap."""
        with self._cond:
            self.state, self.fields = state, dict(fields)
            self._cond.notify_all()
        self.changed()
        forget_caches()

    def launch(self, work, *args, keep: dict | None = None) -> None:
        """``work(*args)`` on a thread of its own: its dict result shown as the job's fields once DONE, or its
        exception as FAILED with one line (``keep``: fields shown either way)."""
        def run() -> None:
            try:
                result = work(*args)
            except Exception as exc:  # noqa: BLE001 - the page gets one line, the log the details
                self.finish(JobState.FAILED, **(keep or {}), error=failed(exc, self.WHAT))
                return
            self.finish(JobState.DONE, **(keep or {}), **result)
        threading.Thread(target=run, name=f"rangekit-{self.WHAT.replace(' ', '-')}", daemon=True).start()
