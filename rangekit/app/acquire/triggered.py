"""A view's frames taken on the projector's trigger: a rig file's ``capture.trigger`` "projector"
(:func:`rangekit.rig.checks.camera_triggered`), the camera a :class:`rangekit.rig.devices.TriggeredCamera`.

For each exposure of a view, :func:`take_triggered` arms the camera, shows every pattern of the view one after
the other at the projector's pace (no pattern delay: each pattern sends the camera its own pulse once it is
shown), then takes the camera's frames in order. Frame ``i`` must carry trigger count ``i + 1``: any other count,
or no frame, is a :class:`rangekit.errors.MissedTrigger` naming the frame and the counts, never a frame kept in
the wrong place. :func:`rangekit.app.acquire.acquire.acquire` then takes the view again from its turntable move
(at most :data:`rangekit.app.acquire.reconnect.MAX_RETAKES` times), the simulator's noise restarted for it, so the
session holds the frames a scan without the fault records.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from rangekit.errors import ConfigError, MissedTrigger
from rangekit.laser.sequence import LaserSequence
from rangekit.rig.checks import camera_triggered

__all__ = ["FRAME_TIMEOUT_S", "uses_trigger", "take_triggered"]

#: Seconds a triggered frame is waited for once every pattern of the view was shown: the projector's latency and
#: a pattern's display are a few refreshes; a frame not there by then never comes.
FRAME_TIMEOUT_S = 1.0


def uses_trigger(camera, rig, spec) -> bool:
    """Whether a view's frames are taken on the projector's trigger: the rig file's ``capture.trigger`` is
    "projector". ConfigError (before any frame) when it is and the scan is a laser scan (the lasers send no
    trigger) or the camera has no triggered capture (``arm_trigger`` and ``capture_triggered``)."""
    if not camera_triggered(rig.capture):
        return False
    if isinstance(spec, LaserSequence):
        raise ConfigError("rig file: capture.trigger 'projector': the projector triggers the camera for coded light; a "
                          "laser scan's lasers send no trigger: set capture.trigger to 'none' for it")
    if not (callable(getattr(camera, "arm_trigger", None)) and callable(getattr(camera, "capture_triggered", None))):
        raise ConfigError(f"rig file: capture.trigger 'projector': this camera ({type(camera).__name__}) has no "
                          "triggered capture; set capture.trigger to 'none' (the scan then waits "
                          "capture.pattern_delay_s after each pattern)")
    return True


def _deferred(camera) -> Callable:
    """``capture_triggered(timeout_s)`` whose frame's image is a function returning it (the simulator's own
    ``capture_triggered_deferred``, else the frame taken now, a copy: a driver may reuse its buffer)."""
    deferred = getattr(camera, "capture_triggered_deferred", None)
    if deferred is not None:
        return deferred

    def capture(timeout_s: float):
        frame = camera.capture_triggered(timeout_s)
        image = frame.image.copy() if isinstance(frame.image, np.ndarray) else frame.image
        return type(frame)(lambda: image, frame.trigger)
    return capture


def take_triggered(camera, light, names: list[str], at: Callable[[str, str | None], None],
                   record: Callable[[int, Callable], None]) -> None:
    """Frames ``0 .. len(names) - 1`` of one exposure of a view on the projector's trigger: the camera armed,
    ``light.show(i)`` for each frame without a wait, then each frame taken and handed to ``record(i, image)``
    (``image`` a function returning the (H, W) array). ``at(step, device)`` is told each step before it runs, so
    that a failure names it. Raises MissedTrigger when frame ``i`` does not carry trigger count ``i + 1``."""
    at("camera armed for the projector's trigger", "camera")
    camera.arm_trigger()
    for i, name in enumerate(names):
        at(f"frame {i} ({name}): {light.device}", light.device)
        light.show(i)
    capture = _deferred(camera)
    for i, name in enumerate(names):
        at(f"frame {i} ({name}): camera", "camera")
        try:
            frame = capture(FRAME_TIMEOUT_S)
        except MissedTrigger as exc:
            raise MissedTrigger(f"no frame for trigger {i + 1}: {exc}") from exc
        if frame.trigger != i + 1:
            missed = f"trigger {i + 1}" if frame.trigger == i + 2 else f"triggers {i + 1}..{frame.trigger - 1}"
            raise MissedTrigger(f"the camera missed {missed}: the frame taken for it carries trigger {frame.trigger}"
                                if frame.trigger > i + 1 else
                                f"the frame taken for trigger {i + 1} carries trigger {frame.trigger} (left over)")
        record(i, frame.image)
