"""Device protocols. Real drivers (:mod:`rangekit.drivers`) and simulated devices (:mod:`rangekit.sim`)
both implement these, and never import each other; acquisition code is written against them only.

Units: angles in radians, images as numpy arrays (RGB channel order, uint8 or uint16).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from rangekit.camera import PinholeCamera

__all__ = ["Camera", "Projector", "Turntable", "RigDevices", "check_pattern"]


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
