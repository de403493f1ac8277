"""A RealSense made of the SDK's own parts: ``rs.software_device`` with a "Stereo Module" sensor (a Z16 depth and
a Y8 infrared stream with their intrinsics, the options a D435 has), fed frames on a thread, in a software-only
``rs.context``. Everything the driver calls is the real pyrealsense2 (pipeline, syncer, options, recorder).

pyrealsense2 2.59 quirks met here:
- ``rs.option_range(min, max, step, default)`` positionally stores the third argument as the default and the
  fourth as the step: ranges are built field by field (:func:`option_range`).
- ``software_device.add_to(ctx)`` leaves the device owned by nobody; the device list the devices-changed callback
  hands out must be kept, or ``query_devices()`` does not list it.
- Recordings are written as ROS2 ``.db3`` files only (``.bag`` is refused by the recorder; still read).
"""

from __future__ import annotations

import json
import threading
import time

import numpy as np

import pyrealsense2 as rs

SERIAL = "817612070001"
DEPTH_UNITS = 0.001


def option_range(lo: float, hi: float, default: float, step: float = 1.0):
    r = rs.option_range()
    r.min, r.max, r.step, r.default = float(lo), float(hi), float(step), float(default)
    return r


def intrinsics(camera):
    """The ``rs.intrinsics`` of a rangekit PinholeCamera without distortion."""
    i = rs.intrinsics()
    i.width, i.height = camera.width, camera.height
    i.fx, i.fy, i.ppx, i.ppy = (float(camera.K[0, 0]), float(camera.K[1, 1]), float(camera.K[0, 2]),
                                float(camera.K[1, 2]))
    i.model = rs.distortion.brown_conrady
    i.coeffs = [float(c) for c in (list(camera.dist) + [0.0] * 5)[:5]]
    return i


class SoftwareRealSense:
    """A software D435 in its own context. ``infrared(exposure_us, gain, n) -> (H, W) uint8`` and ``depth(n) -> (H,
    W) uint16`` make frame ``n`` (1, 2, ...); :meth:`start` feeds them at ``fps`` on a thread until :meth:`stop`. ``paused``
    holds the frames back (a camera that stopped answering)."""

    def __init__(self, camera, *, infrared=None, depth=None, fps: int = 30, serial: str = SERIAL) -> None:
        self.camera, self.fps, self.serial = camera, fps, serial
        self._infrared = infrared or (lambda e, g, n: np.zeros((camera.height, camera.width), np.uint8))
        self._depth = depth or (lambda n: np.zeros((camera.height, camera.width), np.uint16))
        self.device = rs.software_device()
        self.device.register_info(rs.camera_info.name, "Intel RealSense D435 (software)")
        self.device.register_info(rs.camera_info.serial_number, serial)
        self.device.register_info(rs.camera_info.firmware_version, "5.16.0.1")
        self.device.register_info(rs.camera_info.usb_type_descriptor, "3.2")
        self.device.register_info(rs.camera_info.product_line, "D400")
        self.sensor = self.device.add_sensor("Stereo Module")
        intr = intrinsics(camera)
        self.depth_profile = self._stream(rs.stream.depth, 0, 0, 2, rs.format.z16, intr)
        self.ir_profile = self._stream(rs.stream.infrared, 1, 1, 1, rs.format.y8, intr)
        self.sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)
        for option, r in ((rs.option.exposure, option_range(1, 165000, 8500)),
                          (rs.option.gain, option_range(16, 248, 16)),
                          (rs.option.enable_auto_exposure, option_range(0, 1, 1)),
                          (rs.option.emitter_enabled, option_range(0, 1, 1)),
                          (rs.option.laser_power, option_range(0, 360, 150, 30))):
            self.sensor.add_option(option, r, True)
        self.device.create_matcher(rs.matchers.default)
        self.context = rs.context(json.dumps({"device-mask": int(rs.product_line.sw_only), "dds": False,
                                              "inherit": False}))
        self._keep = []
        self.context.set_devices_changed_callback(lambda info: self._keep.append(info.get_new_devices()))
        self.device.add_to(self.context)
        self.paused = threading.Event()
        self._stop = threading.Event()
        self._thread = None
        self.frames_sent = 0

    def _stream(self, kind, index, uid, bpp, fmt, intr):
        s = rs.video_stream()
        s.type, s.index, s.uid, s.width, s.height = kind, index, uid, intr.width, intr.height
        s.fps, s.bpp, s.fmt, s.intrinsics = self.fps, bpp, fmt, intr
        return self.sensor.add_video_stream(s)

    def option(self, option) -> float:
        return float(self.sensor.get_option(option))

    def _frame(self, pixels, profile, bpp, n, ts, **extra):
        f = rs.software_video_frame()
        f.pixels, f.bpp, f.stride = pixels, bpp, bpp * self.camera.width
        f.timestamp, f.domain, f.frame_number = ts, rs.timestamp_domain.system_time, n
        f.profile = profile.as_video_stream_profile()
        for k, v in extra.items():
            setattr(f, k, v)
        self.sensor.on_video_frame(f)

    def _feed(self) -> None:
        n = 0
        while not self._stop.is_set():
            if not self.paused.is_set():
                n += 1
                ts = time.time() * 1000.0
                exposure, gain = self.option(rs.option.exposure), self.option(rs.option.gain)
                ir = np.ascontiguousarray(self._infrared(exposure, gain, n))
                self._frame(ir, self.ir_profile, 1, n, ts)
                depth = np.ascontiguousarray(self._depth(n))
                self._frame(depth, self.depth_profile, 2, n, ts, depth_units=DEPTH_UNITS)
                self.frames_sent = n
            time.sleep(1.0 / self.fps)

    def start(self) -> "SoftwareRealSense":
        self._thread = threading.Thread(target=self._feed, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()


def record(dev: SoftwareRealSense, path, frames: int, *, exposure_us: float = 4000.0, emitter: int = 0) -> list[int]:
    """Record ``frames`` framesets (infrared and depth) of the fed device ``dev`` into ``path`` (a .db3) through the
    SDK's recorder (the pipeline's ``enable_record_to_file``), the sensor's exposure and emitter set first; returns
    the infrared frames' numbers waited for, in order. (A recording of the depth stream alone is refused on playback:
    "File contains extrinsics that do not map to an existing stream".)"""
    cfg = rs.config()
    cfg.enable_device(dev.serial)
    w, h = dev.camera.width, dev.camera.height
    cfg.enable_stream(rs.stream.infrared, 1, w, h, rs.format.y8, dev.fps)
    cfg.enable_stream(rs.stream.depth, 0, w, h, rs.format.z16, dev.fps)
    cfg.enable_record_to_file(str(path))
    pipe = rs.pipeline(dev.context)
    profile = pipe.start(cfg)
    sensor = profile.get_device().query_sensors()[0]
    sensor.set_option(rs.option.exposure, exposure_us)
    sensor.set_option(rs.option.emitter_enabled, emitter)
    numbers = []
    try:
        while len(numbers) < frames:
            fs = pipe.wait_for_frames(3000)
            numbers.append(int(fs.get_infrared_frame(1).get_frame_number()))
    finally:
        pipe.stop()
    return numbers
