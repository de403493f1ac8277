"""The object moving while a coded-light sequence is captured (Fusiello 13.1: a sequential method assumes a still
scene): a slip, a vibration, a breathing subject. The simulator's truth for issue 38's motion detection.

A :class:`Motion` moves the scanned object (the scene's first object; the table stays) along ``direction`` (unit,
world frame) by ``offset_m(t)`` at time ``t``, counted in frames from the first frame's exposure:

- ``slip``: 0 before ``at_frame``, ``amplitude_m`` from then on (the object shifted once);
- ``vibration``: ``amplitude_m sin(2 pi t / period_frames)``;
- ``breathing``: ``amplitude_m (1 - cos(2 pi t / period_frames)) / 2`` (out and back, from rest).

:func:`capture_moving` captures a pattern sequence on a :class:`rangekit.sim.SimRig` with every frame exposed at
its own offset (a global shutter): consecutive frames at the same offset are one ``capture_sequence`` of the moved
scene, so a slip costs two renders of the geometry. The scene is put back afterwards.

A rolling shutter (``readout_frames`` > 0) exposes camera row r of frame k at ``k + readout_frames * r / (H - 1)``:
each band of ``band_rows`` rows takes the offset at its middle row's time, and a frame whose bands differ is rendered
once for each offset and put together band by band (a slip during a frame's readout: its top rows see the object
where it was, its lower rows where it went). Frames rendered more than once draw more of the noise stream, so the
frames after them differ in their noise from a global-shutter capture.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import SceneError
from rangekit.geometry import make_T
from rangekit.sim.scene.passes import pass_scene

__all__ = ["MOTION_KINDS", "Motion", "capture_moving"]

MOTION_KINDS = ("slip", "vibration", "breathing")
#: The largest displacement simulated, metres (``rangekit sim render --motion-mm`` is checked against it).
MAX_AMPLITUDE_M = 0.05


@dataclass(frozen=True)
class Motion:
    """How the object moves during a sequence (module doc). Metres, frames, a world-frame direction."""

    kind: str
    amplitude_m: float
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    at_frame: float = 0.0          # slip: the first frame exposed after the slip
    period_frames: float = 8.0     # vibration, breathing

    def __post_init__(self) -> None:
        if self.kind not in MOTION_KINDS:
            raise SceneError(f"motion: kind must be one of {', '.join(MOTION_KINDS)}, found {self.kind!r}")
        if not (np.isfinite(self.amplitude_m) and abs(self.amplitude_m) <= MAX_AMPLITUDE_M):
            raise SceneError(f"motion: amplitude must be a finite number of metres up to 0.05, found {self.amplitude_m!r}")
        d = np.asarray(self.direction, np.float64)
        if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
            raise SceneError(f"motion: direction must be a non-zero 3-vector, found {self.direction!r}")
        if not (np.isfinite(self.period_frames) and self.period_frames > 0):
            raise SceneError(f"motion: period_frames must be > 0, found {self.period_frames!r}")

    def offset_m(self, t_frames) -> np.ndarray:
        """The displacement along ``direction`` (metres) at times ``t_frames`` (frames since the first)."""
        t = np.asarray(t_frames, np.float64)
        if self.kind == "slip":
            return np.where(t >= self.at_frame, self.amplitude_m, 0.0)
        phase = 2 * np.pi * t / self.period_frames
        if self.kind == "vibration":
            return self.amplitude_m * np.sin(phase)
        return self.amplitude_m * (1 - np.cos(phase)) / 2

    def motion(self, t_frames: float) -> np.ndarray:
        """(4, 4) world-frame motion of the object at time ``t_frames``."""
        return self.motion_by(float(self.offset_m(t_frames)))

    def motion_by(self, offset_m: float) -> np.ndarray:
        """(4, 4) world-frame motion of the object displaced by ``offset_m`` along ``direction``."""
        d = np.asarray(self.direction, np.float64)
        return make_T(np.eye(3), float(offset_m) * d / np.linalg.norm(d))


def capture_moving(sim, patterns, motion: Motion, delay_s: float = 0.0, *, readout_frames: float = 0.0,
                   band_rows: int = 16) -> tuple[list[np.ndarray], np.ndarray]:
    """Capture ``patterns`` on ``sim`` with the object moving by ``motion``, frame k exposed at time k (its first
    row; with ``readout_frames`` > 0 a rolling shutter, module doc); the frames and each frame's first row's offset
    (metres). The scene is restored afterwards."""
    if not (np.isfinite(readout_frames) and 0.0 <= readout_frames <= 1.0):
        raise SceneError(f"capture_moving: readout_frames must be from 0 to 1 frame, found {readout_frames!r}")
    if readout_frames > 0:
        return _rolling(sim, list(patterns), motion, delay_s, readout_frames, max(int(band_rows), 1))
    patterns = list(patterns)
    offsets = motion.offset_m(np.arange(len(patterns)))
    base = sim.scene
    frames: list[np.ndarray] = []
    current = 0.0
    try:
        start = 0
        while start < len(patterns):
            stop = start + 1
            while stop < len(patterns) and offsets[stop] == offsets[start]:
                stop += 1
            if offsets[start] != current:      # a still stretch keeps the scene (and its noise stream) untouched
                sim.set_scene(pass_scene(base, motion.motion(start)) if offsets[start] != 0 else base)
                current = offsets[start]
            frames += sim.capture_sequence(patterns[start:stop], delay_s)
            start = stop
    finally:
        if current != 0.0:
            sim.set_scene(base)
    return frames, offsets


def _rolling(sim, patterns: list, motion: Motion, delay_s: float, readout: float,
             band_rows: int) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`capture_moving` with a rolling shutter: each frame rendered once per distinct band offset."""
    H = sim.rig.camera.height
    starts = np.arange(0, H, band_rows)
    middle = np.minimum(starts + band_rows // 2, H - 1)
    base = sim.scene
    frames: list[np.ndarray] = []
    current = 0.0
    try:
        for k, pattern in enumerate(patterns):
            band_offsets = motion.offset_m(k + readout * middle / max(H - 1, 1))
            image = None
            for offset in np.unique(band_offsets):
                if offset != current:
                    sim.set_scene(pass_scene(base, motion.motion_by(offset)) if offset != 0 else base)
                    current = offset
                shot = sim.capture_sequence([pattern], delay_s)[0]
                if image is None:
                    image = shot.copy()
                for b in np.flatnonzero(band_offsets == offset):
                    image[starts[b]:starts[b] + band_rows] = shot[starts[b]:starts[b] + band_rows]
            frames.append(image)
    finally:
        if current != 0.0:
            sim.set_scene(base)
    return frames, motion.offset_m(np.arange(len(patterns)))
