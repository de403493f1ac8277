"""The simulated rig in real time (``rangekit scan --realtime``, ``ScanOptions(realtime=True)``): the devices
share the wall clock (:class:`rangekit.sim.devices.clock.WallClock`) instead of the virtual one, so a scan
takes as long as on hardware and processing that runs beside it is measured as a user with a rig would see it.

What then takes time, as on a rig:

- each frame: the rig file's ``capture.pattern_delay_s`` after the pattern is shown (acquisition waits it;
  0.1 s when the rig file gives none, as on hardware), then the camera's next frame period at its frame rate
  (the rig file's ``capture.camera.fps``, 30 by default: an exposure of up to 33 ms);
- the projector's display latency, :data:`REALTIME_LATENCY_S` (under the pattern delay, as ``rangekit check``
  would find it; a frame taken sooner sees the previous pattern);
- each turntable move: :data:`REALTIME_TURNTABLE_DEG_S`, then the rig file's ``capture.turntable_settle_s``
  (0.5 s by default).

A camera triggered by the projector (``rangekit scan --triggered``, the rig file's ``capture.trigger``
"projector"; a new coded-light ``--realtime`` scan models that rig, issue 51: ``ScanOptions.sim_triggered``) waits
no pattern delay: each pattern is shown for the whole refreshes (60 Hz) its exposure spans,
the view's patterns one after the other, the frames exposed on the projector's VSYNC after its latency
(:mod:`rangekit.sim.devices.trigger`).

The frames are the same bytes as without real time: each sees the pattern shown for it.
"""

from __future__ import annotations

from rangekit.sim.devices.clock import WallClock

__all__ = ["REALTIME_LATENCY_S", "REALTIME_TURNTABLE_DEG_S", "realtime_options"]

#: The simulated projector's display latency in real time (seconds): a DLP projector's frame or two.
REALTIME_LATENCY_S = 0.05
#: The simulated turntable's speed in real time (degrees a second): a Ciclop/Horus stepper board's.
REALTIME_TURNTABLE_DEG_S = 30.0


def realtime_options(pattern_delay_s: float, *, triggered: bool = False) -> dict:
    """:class:`rangekit.sim.devices.sim_rig.SimRig` keywords for real time, for a scan waiting ``pattern_delay_s``
    after each pattern: the wall clock, the projector's latency (at most half the delay; ``triggered``, a camera
    triggered by the projector, which waits no delay: :data:`REALTIME_LATENCY_S`), the turntable's speed."""
    latency = REALTIME_LATENCY_S if triggered else min(REALTIME_LATENCY_S, 0.5 * float(pattern_delay_s))
    return {"clock": WallClock(), "latency_s": latency, "turntable_speed_deg_s": REALTIME_TURNTABLE_DEG_S}
