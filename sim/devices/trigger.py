"""The projector's VSYNC triggering the simulated camera: a rig file's ``capture.trigger`` "projector"
(:func:`rangekit.rig.checks.camera_triggered`), the :class:`rangekit.rig.devices.TriggeredCamera` of the simulator.

On the clock the devices share, with the projector's refresh period ``T = 1 / refresh_hz`` (the rig file's
``devices.projector.refresh_hz``, else :data:`DEFAULT_REFRESH_HZ`):

- ``projector.show(image)`` at time t is the host's flip: it waits for the first refresh tick ``v`` at or after t
  and after the previous pattern's ``hold`` refreshes, and returns at ``v`` (the host may show the next pattern at
  once: the projector takes one new pattern every ``hold`` refreshes);
- the projector shows the pattern from ``v + L`` for ``hold`` refreshes (``L``: its display latency rounded up to
  whole refreshes) and sends one trigger pulse at ``v + L``, its VSYNC of the first refresh showing the pattern;
- the armed camera counts every pulse and exposes on it for its exposure time, which ``hold`` (the camera's
  exposure in whole refreshes, at least 1) keeps inside the pattern's display: no pattern delay is waited, no
  frame sees two patterns. The frame is ready at the end of the pattern's display, ``v + L + hold * T``.

A missed trigger (:meth:`VsyncTrigger.miss`, :meth:`rangekit.sim.devices.sim_rig.SimRig.inject_missed_trigger`):
the camera counts the pulse but exposes no frame for it (it was busy), so its next frame carries a count one
higher than the host expects; with no later pulse, the camera's wait times out.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from rangekit.errors import DeviceError, MissedTrigger
from rangekit.sim.devices.clock import TICK_EPS_S, next_tick

__all__ = ["DEFAULT_REFRESH_HZ", "TriggerPulse", "VsyncTrigger"]

#: The simulated projector's refresh rate (Hz) when the rig file gives no ``devices.projector.refresh_hz``.
DEFAULT_REFRESH_HZ = 60.0


@dataclass(frozen=True, eq=False)
class TriggerPulse:
    """A pulse on the camera's trigger input: at ``time_s`` (seconds, shared clock) the projector starts showing
    ``image`` for ``hold_s`` seconds."""

    time_s: float
    image: np.ndarray
    hold_s: float


class VsyncTrigger:
    """The trigger line between the simulated projector and camera (see the module docstring).

    ``clock``: the clock the devices share; ``refresh_hz``: the projector's refresh rate (Hz, > 0);
    ``latency_s``: its display latency (seconds, >= 0).
    """

    def __init__(self, clock, refresh_hz: float, latency_s: float) -> None:
        hz = float(refresh_hz)
        if not (math.isfinite(hz) and hz > 0):
            raise DeviceError(f"simulated projector: refresh_hz must be a number of hertz > 0, found {refresh_hz!r}")
        self.clock, self.period_s = clock, 1.0 / hz
        self.latency_s = float(latency_s)
        self.hold = 1                  # refreshes each pattern is shown for: the camera's exposure, at least one
        self.count = 0                 # pulses the camera counted since it was armed
        self._pulses: deque[TriggerPulse] = deque()
        self._next_flip = -math.inf    # the earliest time the projector takes a new pattern
        self._miss: int | None = None  # pulses still to take before the one the camera misses

    def flip(self, image: np.ndarray) -> None:
        """The projector takes ``image`` at its next refresh tick the previous pattern leaves free, waiting on
        the clock until then, and sends its pulse once the image is shown (after the latency)."""
        T = self.period_s
        v = next_tick(max(self.clock.now(), self._next_flip), T)
        self.clock.sleep(max(0.0, v - self.clock.now()))
        self._next_flip = v + self.hold * T
        shown = next_tick(v + self.latency_s, T)
        self._pulses.append(TriggerPulse(shown, image, self.hold * T))
        if len(self._pulses) > 4096:      # nobody takes triggered frames: keep the latest only
            self._pulses.popleft()

    def arm(self, exposure_us: float) -> None:
        """Start counting from 0, the pulses not yet taken dropped; each pattern from now is shown for the whole
        refreshes ``exposure_us`` (microseconds) spans (within 1 %), at least one."""
        periods = float(exposure_us) * 1e-6 / self.period_s
        self.hold = max(1, math.ceil(periods - 0.01))
        self.count = 0
        self._pulses.clear()

    def miss(self, after: int = 0) -> None:
        """The camera misses the (after + 1)-th pulse it takes from now (counted, no frame)."""
        self._miss = int(after)

    def next_pulse(self, timeout_s: float) -> tuple[int, TriggerPulse]:
        """The next pulse the camera exposes a frame on and its count, the clock advanced to the end of that
        frame (the end of the pattern's display). Raises MissedTrigger, after ``timeout_s`` on the clock, when
        no pulse is left."""
        while self._pulses:
            pulse = self._pulses.popleft()
            self.count += 1
            if self._miss is not None:
                self._miss -= 1
                if self._miss < 0:
                    self._miss = None
                    continue            # counted, no frame: the camera was busy
            ready = pulse.time_s + pulse.hold_s
            if ready > self.clock.now() + TICK_EPS_S:
                self.clock.sleep(ready - self.clock.now())
            return self.count, pulse
        self.clock.sleep(max(0.0, float(timeout_s)))
        raise MissedTrigger(f"camera (simulated): no triggered frame within {float(timeout_s):g} s ({self.count} "
                            "pulse(s) counted since it was armed, no frame left)")
