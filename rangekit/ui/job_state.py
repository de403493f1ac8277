"""What a page sees of a job (a check, a calibration, a registration) that ended in an error: one line.

A :class:`rangekit.errors.RangekitError` is rangekit's own one-line message, shown as it is (the command line's
words). Anything else is a bug: its traceback goes to the server's log and the page gets one line naming it, never
the traceback.
"""

from __future__ import annotations

from rangekit.errors import RangekitError
from rangekit.progress import LOGGER

__all__ = ["failed"]


def failed(exc: Exception, what: str) -> dict:
    """``{"state": "failed", "error": one line}`` for a job ``what`` ("check", "calibration"...) that raised ``exc``."""
    if isinstance(exc, RangekitError):
        return {"state": "failed", "error": str(exc)}
    LOGGER.error("%s failed", what, exc_info=exc)
    return {"state": "failed", "error": f"the {what} failed: {type(exc).__name__}: {exc}"}
