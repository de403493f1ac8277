"""Retrying a device that went away: :func:`retry` calls an attempt until it succeeds or the time is up.

The drivers' ``reconnect(timeout_s)`` methods (turntable boards, the projector's display) use it; acquisition
calls them with the rig file's ``devices.<device>.reconnect_timeout_s``.
"""

from __future__ import annotations

import time
from typing import Callable, TypeVar

from rangekit.errors import DeviceDisconnected, DeviceTimeout, ProtocolError

__all__ = ["retry"]

T = TypeVar("T")
#: What a device that is not back yet raises: retried.
NOT_BACK = (DeviceDisconnected, DeviceTimeout, ProtocolError)


def retry(attempt: Callable[[float], T], timeout_s: float, *, errors: tuple = NOT_BACK, pause_s: float = 0.1,
          min_s: float = 0.05) -> T:
    """``attempt(left_s)``'s result, the attempt repeated after ``pause_s`` seconds while it raises one of
    ``errors``, until ``timeout_s`` seconds have passed (then its last error is raised). ``left_s``: the seconds
    left, at least ``min_s`` (an attempt's replies should wait no longer). Other errors are raised at once."""
    deadline = time.monotonic() + float(timeout_s)
    while True:
        try:
            return attempt(max(min_s, deadline - time.monotonic()))
        except errors:
            if time.monotonic() >= deadline:
                raise
            time.sleep(min(pause_s, max(0.0, deadline - time.monotonic())))
