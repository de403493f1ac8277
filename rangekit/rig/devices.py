"""Device protocols. Real drivers (:mod:`rangekit.drivers`) and simulated devices (:mod:`rangekit.sim`)
both implement these, and never import each other; acquisition code is written against them only.

Units: angles in radians, images as numpy arrays (RGB channel order, uint8 or uint16).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from rangekit.camera import PinholeCamera

__all__ = ["Camera", "TriggeredCamera", "TriggeredFrame", "Projector", "Turntable", "RigDevices", "check_pattern"]


def check_pattern(image: np.ndarray, resolution: tuple[int, int], name: str = "projector") -> np.ndarray:
    """``image`` as an array if it fits a projector of ``resolution`` (width, height): (H, W) or (H, W, 3).

    Raises PatternError naming the projector, the expected and the found shape.
    """
    from rangekit.errors import PatternError

    img = np.asarray(image)
    W, H = resolution
    if img.shape[:2] != (H, W) or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise PatternError(f"projector {name!r} is {W}x{H}: a pattern must have shape ({H}, {W}) or ({H}, {W}, 3), "
                           f"found {img.shape}")
    return img


@runtime_checkable
class Camera(Protocol):
    """Something that takes pictures."""

    @property
    def calibration(self) -> PinholeCamera:
        """Its calibration: intrinsics, distortion, size and pose ``T_world_cam``."""
        ...

    def capture(self) -> np.ndarray:
        """One exposure: (H, W) or (H, W, 3) uint8/uint16, taken after the call started."""
        ...


@dataclass(frozen=True, eq=False)
class TriggeredFrame:
    """A frame a trigger exposed.

    ``image``: (H, W) or (H, W, 3) uint8/uint16, as :meth:`Camera.capture` gives it; or (the simulator's
    ``capture_triggered_deferred``) a function of no argument that returns it, rendered where the frame is written.
    ``trigger``: the camera's count of trigger pulses since :meth:`TriggeredCamera.arm_trigger`, at the pulse that
    exposed this frame (1 = the first pulse after arming). Pulses the camera received but exposed no frame for (it
    was busy) are counted too, so a frame after a missed trigger carries a count one too high.
    """

    image: np.ndarray | Callable[[], np.ndarray]
    trigger: int


@runtime_checkable
class TriggeredCamera(Camera, Protocol):
    """A camera triggered by the projector (a rig file's ``capture.trigger`` "projector",
    :func:`rangekit.rig.checks.camera_triggered`): each new pattern the projector shows sends one pulse (its VSYNC
    at the first refresh showing the pattern) to the camera's trigger input, and the camera exposes while that
    pattern is shown. Acquisition (:mod:`rangekit.app.acquire.triggered`) arms the camera, shows a view's
    patterns at the projector's pace without waiting between them, then takes the view's frames in order, each of
    which must carry the next trigger count, 1, 2, ...; any other count (or no frame) is a missed trigger,
    :class:`rangekit.errors.MissedTrigger`, and the view is taken again.
    """

    def arm_trigger(self) -> None:
        """Wait for triggers from now on: frames not yet taken are dropped and the trigger count restarts at 0.
        Raises DeviceError when the camera cannot be triggered as the rig file says (no trigger input, an
        exposure longer than the projector shows a pattern)."""
        ...

    def capture_triggered(self, timeout_s: float) -> TriggeredFrame:
        """The next frame a trigger exposed, oldest first, waiting up to ``timeout_s`` seconds for it. A
        camera that drops frames must still count the pulses (a hardware trigger counter, e.g. GenICam's
        ``Counter0`` of ``Line0`` rising edges read as chunk data), never renumber the frames it delivers.
        Raises MissedTrigger when no frame comes in time."""
        ...


@runtime_checkable
class Projector(Protocol):
    """Something that shows pattern images."""

    @property
    def calibration(self) -> PinholeCamera:
        """Its calibration as an inverse camera."""
        ...

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels; every pattern shown must have this size."""
        ...

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` ((height, width) or (height, width, 3), uint8) until the next call.

        Raises PatternError if the size is not the projector's.
        """
        ...


@runtime_checkable
class Turntable(Protocol):
    """A motorised rotation stage."""

    @property
    def angle(self) -> float:
        """Current angle in radians (0 = where it was zeroed)."""
        ...

    def rotate_to(self, angle: float) -> None:
        """Move to an absolute angle in radians and return once the motion has finished."""
        ...


@runtime_checkable
class RigDevices(Protocol):
    """The devices of one scanner, grouped (the rig file's calibration is :class:`rangekit.rig.rig_file.Rig`)."""

    camera: Camera
    projector: Projector
    turntable: Turntable | None
