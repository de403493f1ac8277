"""A RealSense's depth stream as an active-stereo range sensor (Fusiello's book, 13.2.1: two cameras and a
projected random texture; the camera matches the pair on board).

The dot emitter is switched on (``emitter_enabled`` 1, and ``laser_power`` when given), the Z16 depth stream of
the requested size is started, ``settle_frames`` frames are dropped so that the emitter's light is in the one
kept, and the frame is turned into metres with the depth units the SDK reports (``frame.get_units()``, a float32:
its shortest decimal, 0.001 and not 0.0010000000475; 0 = no match, NaN here). The range map (the distance along each pixel's ray) is computed with the stream's own
intrinsics (:func:`rangekit.drivers.realsense.device.pinhole_from_intrinsics`, :func:`rangekit.tof.range_maps.
depth_to_range`). A recording (``bag``) gives its first depth frame, with the emitter as recorded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.drivers.realsense.device import (CHECK_CABLE, device_serial, find_device, pinhole_from_intrinsics,
                                               read_option, set_option, stream_sensor)
from rangekit.drivers.realsense.recording import RecordingStream
from rangekit.errors import ConfigError, DeviceError, DeviceTimeout, one_line
from rangekit.rig.checks import DEFAULT_SEARCH_S

__all__ = ["RealSenseRange", "capture_range", "depth_metres"]


@dataclass(frozen=True, eq=False)
class RealSenseRange:
    """One depth frame: ``depth`` (H, W) float64 camera-frame z and ``range`` (H, W) float64 distance along each
    pixel's ray, metres, NaN where the camera found no match; ``camera`` the depth stream's intrinsics as the SDK
    reports them (``T_world_cam`` = I); ``depth_units`` metres per Z16 unit; ``emitter`` the emitter state read
    back (None: no such control); ``frame_number`` the SDK's; ``serial`` the camera's."""

    depth: np.ndarray
    range: np.ndarray
    camera: PinholeCamera
    depth_units: float
    emitter: float | None
    frame_number: int
    serial: str


def depth_metres(z16: np.ndarray, depth_units: float) -> np.ndarray:
    """(H, W) float64 metres of a Z16 frame (``depth_units`` metres a unit), NaN where it is 0 (no match)."""
    z = np.asarray(z16, dtype=np.float64) * float(depth_units)
    z[np.asarray(z16) == 0] = np.nan
    return z


def capture_range(serial: str | None = None, *, bag: str | Path | None = None, size: tuple[int, int] = (848, 480),
                  fps: int = 30, laser_power: float | None = None, settle_frames: int = 5,
                  search_timeout_s: float = DEFAULT_SEARCH_S, frame_timeout_s: float = 3.0,
                  context=None) -> RealSenseRange:
    """One depth frame of a RealSense (module doc) with its emitter on.

    ``laser_power``: the emitter's power as a fraction 0..1 of its range (None: as it is). Raises
    DeviceDisconnected when the camera is not found; DeviceError when the stream or the emitter cannot be set;
    DeviceTimeout when no frame comes; FileFormatError for a ``bag`` that is not a recording."""
    import pyrealsense2 as rs

    if laser_power is not None and not 0.0 <= laser_power <= 1.0:
        raise ConfigError(f"capture_range: laser_power must be a fraction 0..1 of the emitter's power, found "
                          f"{laser_power!r}")
    ctx = rs.context() if context is None else context
    size = (int(size[0]), int(size[1]))
    if bag is not None:
        rec = RecordingStream(rs, ctx, bag, rs.stream.depth, size=size)
        try:
            frame = rec.next_frame(frame_timeout_s)
            camera = pinhole_from_intrinsics(rs, rec.profile.as_video_stream_profile().get_intrinsics(), name="depth",
                                             where=rec.name)
            emitter = read_option(rs, rec.sensor, rs.option.emitter_enabled)
            return _range(frame.data, frame.units, camera, emitter, frame.number, rec.serial)
        finally:
            rec.close()
    serial = device_serial(rs, find_device(rs, ctx, serial, search_timeout_s))
    name = f"RealSense {serial}"
    cfg = rs.config()
    cfg.enable_device(serial)
    cfg.enable_stream(rs.stream.depth, size[0], size[1], rs.format.z16, int(fps))
    pipeline = rs.pipeline(ctx)
    try:
        profile = pipeline.start(cfg)
    except RuntimeError as exc:
        raise DeviceError(f"{name}: cannot stream depth at {size[0]}x{size[1]} Z16 {fps} fps ({one_line(exc)}); "
                          "choose a size and rate the camera offers (the RealSense Viewer lists them)") from exc
    try:
        sensor = stream_sensor(rs, profile.get_device(), rs.stream.depth, name)
        _emitter_on(rs, sensor, laser_power, name)
        stream = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        camera = pinhole_from_intrinsics(rs, stream.get_intrinsics(), name="depth", where=name)
        frame = _depth_frame(pipeline, settle_frames, frame_timeout_s, name)
        return _range(np.asanyarray(frame.get_data()), frame.get_units(), camera,
                      read_option(rs, sensor, rs.option.emitter_enabled), int(frame.get_frame_number()), serial)
    finally:
        pipeline.stop()


def _range(z16: np.ndarray, units: float, camera: PinholeCamera, emitter, number: int, serial: str) -> RealSenseRange:
    """The :class:`RealSenseRange` of a Z16 frame; ``units`` the SDK's float32, taken as its shortest decimal."""
    from rangekit.tof.range_maps import depth_to_range

    units = float(str(np.float32(units)))    # the decimal the camera was set to (0.001), not float32's 0.0010000000475
    depth = depth_metres(z16, units)
    return RealSenseRange(depth, depth_to_range(depth, camera), camera, units, emitter, number, serial)


def _emitter_on(rs, sensor, laser_power: float | None, name: str) -> None:
    """Switch the dot emitter on (and its power to ``laser_power`` of its range), read back."""
    if not sensor.supports(rs.option.emitter_enabled):
        raise DeviceError(f"{name}: has no dot emitter (emitter_enabled); active stereo needs one (a D415, D435, "
                          "D455 has it)")
    set_option(rs, sensor, rs.option.emitter_enabled, 1, name=name, field="the dot emitter (on for active stereo)")
    if laser_power is not None and sensor.supports(rs.option.laser_power):
        r = sensor.get_option_range(rs.option.laser_power)
        value = r.min + round(laser_power * (r.max - r.min) / max(r.step, 1e-9)) * max(r.step, 1e-9)
        set_option(rs, sensor, rs.option.laser_power, min(value, r.max), name=name, field="--dots (laser_power)")


def _depth_frame(pipeline, settle: int, timeout_s: float, name: str):
    """The depth frame after ``settle`` dropped ones."""
    deadline = time.monotonic() + timeout_s
    for k in range(settle + 1):
        left = deadline - time.monotonic()
        try:
            frames = pipeline.wait_for_frames(max(1, int(left * 1000)))
        except RuntimeError as exc:
            raise DeviceTimeout(f"{name}: no depth frame within {timeout_s:g} s after {k} ({one_line(exc)}); "
                                f"{CHECK_CABLE}") from exc
    return frames.get_depth_frame()
