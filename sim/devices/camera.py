"""The simulated camera of :class:`rangekit.sim.devices.sim_rig.SimRig`: its controls, auto-exposure and frame clock."""

from __future__ import annotations

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.rig.camera_controls import CameraControls
from rangekit.rig.devices import TriggeredFrame
from rangekit.errors import DeviceError
from rangekit.sim.devices.clock import next_tick
from rangekit.sim.imaging.sensor import REF_EXPOSURE_US, REF_ISO, Exposure, auto_exposure_step, exposure_for

__all__ = ["SimCamera"]


class SimCamera:
    """Renders the scene at the sim turntable's angle, lit by the sim projector or, on a rig made with
    ``light="laser"``, by the line laser switched on (none on: the laser-off, ambient image).

    Controls (:meth:`set_controls`): exposure and ISO scale the signal and noise as
    :mod:`rangekit.sim.imaging.sensor` describes (the defaults ``CameraControls()`` are its reference);
    ``exposure_us`` None runs its auto-exposure, frame to frame. White balance and focus are accepted and
    have no effect (the simulated sensor is neutral and always in focus). A laser-lit rig renders at the
    reference exposure only. Each capture exposes the frame at the next tick of the shared clock (frame
    period ``1 / fps``) and returns at the end of that frame period; ``last_frame_time`` is its start.

    On a rig whose file says ``capture.trigger`` "projector" the camera is also a
    :class:`rangekit.rig.devices.TriggeredCamera`: :meth:`arm_trigger`, :meth:`capture_triggered`, each frame
    exposed by the projector's VSYNC pulse (:mod:`rangekit.sim.devices.trigger`).
    """

    def __init__(self, rig) -> None:        # rig: the SimRig it belongs to
        self._rig = rig
        self.controls = CameraControls()
        self._ae_value = REF_EXPOSURE_US
        self.last_frame_time: float | None = None
        self.last_exposure = Exposure()

    @property
    def calibration(self) -> PinholeCamera:
        return self._rig.rig.camera

    @property
    def auto_exposure(self) -> bool:
        return self.controls.auto_exposure

    def set_controls(self, controls: CameraControls) -> None:
        """Apply ``controls``; auto-exposure starts from the camera's present exposure."""
        if not isinstance(controls, CameraControls):
            raise DeviceError(f"simulated camera: set_controls expects a CameraControls, found "
                              f"{type(controls).__name__}")
        if self._rig.light == "laser" and (controls.exposure_us, controls.iso) != (REF_EXPOSURE_US, REF_ISO):
            raise DeviceError(f"simulated camera: a laser-lit rig renders at the reference exposure only "
                              f"(exposure_us {REF_EXPOSURE_US:g}, iso {REF_ISO}), found exposure_us "
                              f"{controls.exposure_us}, iso {controls.iso}")
        if controls.auto_exposure and not self.auto_exposure:
            self._ae_value = self.last_exposure.exposure_us * self.last_exposure.iso / REF_ISO
        self.controls = controls
        if not controls.auto_exposure:
            self.last_exposure = Exposure(controls.exposure_us, controls.iso or REF_ISO)

    def exposure(self) -> Exposure:
        """The exposure and ISO of the next frame."""
        c = self.controls
        if c.auto_exposure:
            return exposure_for(self._ae_value, c.fps)
        return Exposure(c.exposure_us, c.iso if c.iso is not None else REF_ISO)

    def next_frame(self) -> float:
        """Start the next frame on the shared clock: its exposure starts at the next frame tick, the call
        returns (the clock is advanced) at the end of that frame period. Returns the frame's time."""
        period = 1.0 / self.controls.fps
        clock = self._rig.clock
        t = next_tick(clock.now(), period)
        clock.sleep(t + period - clock.now())
        self.last_frame_time = t
        return t

    def observe(self, image: np.ndarray) -> None:
        """Auto-exposure's step after ``image`` (nothing with a locked exposure)."""
        if self.auto_exposure:
            m = self._rig.imaging.max_value
            self._ae_value = auto_exposure_step(self._ae_value, float(image.mean()) / m, m)

    def capture(self) -> np.ndarray:
        return self.capture_deferred()()

    def capture_deferred(self):
        """Take the next frame now (fault, clock, pattern seen, noise generator, exposure: the state a
        :meth:`capture` would use) and return a function that renders it: the same bytes as
        :meth:`capture`, wherever and whenever it is called (acquisition renders on worker threads). Under
        auto-exposure, or with the lasers, the frame is rendered at once (the next frame depends on it)."""
        self._rig._faults.tick("camera")
        exposure = self.exposure()
        t = self.next_frame()
        self.last_exposure = exposure
        if self._rig.light == "laser":
            out = self._rig.laser_image()
            return lambda: out
        image = self._rig.projector.image_at(t)
        renderer, rng = self._rig.capture_renderer(), self._rig.rng_for(image)
        if not self.auto_exposure:
            return lambda: renderer.render(image, rng, exposure)
        out = renderer.render(image, rng, exposure)
        self.observe(out)
        return lambda: out

    # ---------------------------------------------------------------- triggered by the projector
    def _trigger(self):
        trigger = self._rig.trigger
        if trigger is None:
            raise DeviceError("simulated camera: not triggered; the rig file's capture.trigger is not 'projector'")
        return trigger

    def arm_trigger(self) -> None:
        """Count the projector's pulses from 0, frames not taken dropped; each pattern is shown for the whole
        refreshes the camera's exposure spans. Refuses auto-exposure (the exposure sets how long a pattern is
        shown) and the lasers (they send no trigger)."""
        trigger = self._trigger()
        if self.auto_exposure or self._rig.light == "laser":
            raise DeviceError("simulated camera: a camera triggered by the projector needs a locked exposure and the "
                              f"projector's light, found exposure_us {self.controls.exposure_us}, light "
                              f"{self._rig.light!r}")
        trigger.arm(self.controls.exposure_us)

    def capture_triggered(self, timeout_s: float) -> TriggeredFrame:
        """The next frame the projector's pulse exposed (:class:`rangekit.rig.devices.TriggeredFrame`)."""
        frame = self.capture_triggered_deferred(timeout_s)
        return TriggeredFrame(frame.image(), frame.trigger)

    def capture_triggered_deferred(self, timeout_s: float) -> TriggeredFrame:
        """:meth:`capture_triggered` with the image a function that renders it (as :meth:`capture_deferred`):
        the pattern the pulse showed, the noise of the same capture state, so the same bytes as an untriggered
        capture of that pattern. ``last_frame_time`` is the pulse's time, ``last_exposure_window`` the exposure
        (start, end) and ``last_shown_window`` the pattern's display (start, end), seconds on the shared clock."""
        trigger = self._trigger()
        self._rig._faults.tick("camera")
        exposure = self.exposure()
        count, pulse = trigger.next_pulse(timeout_s)
        self.last_frame_time, self.last_exposure = pulse.time_s, exposure
        self.last_exposure_window = (pulse.time_s, pulse.time_s + exposure.exposure_us * 1e-6)
        self.last_shown_window = (pulse.time_s, pulse.time_s + pulse.hold_s)
        image, renderer = pulse.image, self._rig.capture_renderer()
        rng = self._rig.rng_for(image)
        return TriggeredFrame(lambda: renderer.render(image, rng, exposure), count)
