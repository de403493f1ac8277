"""The clock the simulated devices share: when a pattern is shown, when a frame is exposed.

:class:`SimClock` is virtual: :meth:`SimClock.sleep` advances it without waiting, so a test of the
projector's latency (``SimProjector(latency_s=...)``) runs in no time and is exact. Each camera capture
starts at the next frame tick (a whole number of frame periods ``1 / fps`` from 0, at or after the call)
and returns at the end of that frame period (:meth:`rangekit.sim.devices.sim_rig.SimCamera.capture`). Code that
waits for the devices (acquisition's pattern delay, calibration's) waits through ``devices.sleep`` when the
devices have one, so the simulator's virtual time, not the wall clock, passes.

:class:`WallClock` is the real time (``time.monotonic``, ``time.sleep``), for a simulator that should
take as long as hardware.
"""

from __future__ import annotations

import math
import time

from rangekit.errors import InputError

__all__ = ["SimClock", "WallClock", "next_tick", "TICK_EPS_S"]

#: Times closer than this (seconds) are the same instant (floating-point sums of frame periods).
TICK_EPS_S = 1e-9


class SimClock:
    """Virtual time in seconds, from ``start``; :meth:`sleep` advances it at once."""

    virtual = True   # its sleeps take no real time (acquisition opens no quiet window for them)

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def sleep(self, seconds: float) -> None:
        """Advance by ``seconds`` (>= 0) without waiting."""
        s = float(seconds)
        if not math.isfinite(s) or s < 0:
            raise InputError(f"SimClock.sleep: expected a finite number of seconds >= 0, found {seconds!r}")
        self._t += s


class WallClock:
    """The real time: ``time.monotonic()`` and ``time.sleep``."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


def next_tick(t: float, period: float) -> float:
    """The first whole multiple of ``period`` at or after ``t`` (seconds)."""
    return math.ceil(t / period - TICK_EPS_S / period) * period
