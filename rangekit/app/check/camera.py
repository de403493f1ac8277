"""``rangekit check --rig`` on a rig file whose ``devices`` name a camera but no projector display: the camera alone.

Without a projector nothing can be shown, so the exposure suggestion, the latency and the test view of
:mod:`rangekit.app.check.steps` cannot run. What a camera alone tells (a laser rig, or a camera being set up before
its projector):

- frames grabbed in the camera's order: how many, their size and dtype, the frame period measured on their arrival
  times, and (a camera giving frame ids: ``camera.last_frame_id``) how many were dropped or repeated;
- the last frame's saturated and too-dark fractions of all pixels (no object mask: nothing lit it);
- the device's *limits*: what its driver could not apply because the device lacks the node (``camera.limits``,
  e.g. a GenICam camera without ``ExposureTime``), each one line.

It writes ``check.json`` (:meth:`CameraCheck.to_dict`) and ``check.png`` (the last frame), and leaves the rig file as
it is (no latency was measured).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from rangekit.app.check.steps import MIN_CONFIDENCE

__all__ = ["CameraCheck", "FRAMES", "check_camera"]

#: Frames grabbed by the camera check.
FRAMES = 30


@dataclass(frozen=True)
class CameraCheck:
    """What the camera check measured: frame counts, the frame period (seconds), fractions of all pixels."""

    frames: int
    width: int
    height: int
    dtype: str
    frame_period_s: float | None
    dropped: int | None            # frames the ids skipped (None: the camera gives no frame ids)
    repeated: int | None           # frames whose id did not advance
    saturated_fraction: float
    dark_fraction: float
    limits: tuple[str, ...]

    def to_dict(self) -> dict:
        """check.json."""
        return {"camera_only": True, "frames": self.frames, "width": self.width, "height": self.height,
                "dtype": self.dtype, "frame_period_s": self.frame_period_s, "dropped_frames": self.dropped,
                "repeated_frames": self.repeated, "saturated_fraction": self.saturated_fraction,
                "dark_fraction": self.dark_fraction, "camera_limits": list(self.limits)}

    def lines(self) -> list[str]:
        """What the command prints, one line each."""
        period = "no frame period (one frame)" if self.frame_period_s is None else \
            f"frame period {self.frame_period_s * 1e3:.1f} ms ({1 / self.frame_period_s:.1f} fps)"
        ids = "no frame ids to check" if self.dropped is None else \
            f"{self.dropped} dropped, {self.repeated} repeated (frame ids)"
        out = [f"camera: {self.frames} frames of {self.width}x{self.height} {self.dtype}, {period}, {ids}",
               f"last frame: {self.saturated_fraction:.2%} of the pixels saturated, {self.dark_fraction:.2%} below "
               f"{MIN_CONFIDENCE:.0%} of full scale"]
        out += [f"limit of the device: {line}" for line in self.limits] or ["limits of the device: none met"]
        out.append("no projector display in the rig file (devices.projector.display): exposure suggestion, latency "
                   "and test view skipped; the rig file is not changed")
        return out


def check_camera(camera, full_scale: float, *, frames: int = FRAMES) -> tuple[CameraCheck, np.ndarray]:
    """Grab ``frames`` frames from ``camera`` in its order (``next_frame`` where the camera has it, else
    ``capture``) and measure them (module docstring); the result and the last frame."""
    grab = getattr(camera, "next_frame", None) or camera.capture
    times, ids, image = [], [], None
    for _ in range(frames):
        image = np.asarray(grab())
        times.append(getattr(camera, "last_frame_time", None) or time.monotonic())
        ids.append(getattr(camera, "last_frame_id", None))
    steps = np.diff(ids) if None not in ids else None
    grey = image if image.ndim == 2 else image.max(axis=2)
    result = CameraCheck(
        frames=frames, width=int(image.shape[1]), height=int(image.shape[0]), dtype=str(image.dtype),
        frame_period_s=float(np.median(np.diff(times))) if frames > 1 else None,
        dropped=None if steps is None else int(np.sum(np.maximum(steps - 1, 0))),
        repeated=None if steps is None else int(np.sum(steps <= 0)),
        saturated_fraction=float(np.mean(grey >= full_scale)),
        dark_fraction=float(np.mean(grey < MIN_CONFIDENCE * full_scale)),
        limits=tuple(getattr(camera, "limits", ())))
    return result, image
