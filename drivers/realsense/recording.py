"""A RealSense recording (``.bag``/``.db3``) played one stream at a time, every frame in order, none dropped.

A pipeline over a recording delivers frames through a queue that drops the oldest when the reader is slow (a
scan waits its pattern delay between frames), even with ``set_real_time(False)``. Here the stream's sensor is
started with a callback that blocks until the frame is taken: the SDK's playback thread waits for the reader,
so the frames come as recorded, however slowly they are read (``tests/drivers/test_realsense_camera.py``).
"""

from __future__ import annotations

import queue
import threading
from pathlib import Path

import numpy as np

from rangekit.drivers.realsense.device import open_recording, stream_sensor
from rangekit.errors import DeviceError

__all__ = ["RecordedFrame", "RecordingStream"]


class RecordedFrame:
    """One played frame: ``data`` its pixels (a copy), ``number`` the SDK's frame number, ``units`` metres a unit
    of a depth frame (None otherwise)."""

    __slots__ = ("data", "number", "units")

    def __init__(self, data: np.ndarray, number: int, units: float | None) -> None:
        self.data, self.number, self.units = data, number, units


class RecordingStream:
    """Play ``stream`` (an ``rs.stream``; ``index`` for the infrared imagers) of the recording ``path`` at ``size``
    (width, height). ``sensor`` is the recorded sensor (its options: the recorded values), ``profile`` the
    stream's profile (``.as_video_stream_profile().get_intrinsics()``), ``serial`` the recorded camera's.

    Raises FileFormatError for a file that is not a recording; DeviceError when it holds no such stream."""

    def __init__(self, rs, ctx, path: str | Path, stream, *, index: int = 0, size: tuple[int, int]) -> None:
        self.path = Path(path)
        self.serial = open_recording(rs, ctx, self.path)
        self.name = f"RealSense {self.serial} (recording {self.path})"
        self._device = ctx.load_device(str(self.path))
        self._device.as_playback().set_real_time(False)
        self.sensor = stream_sensor(rs, self._device, stream, self.name)
        w, h = size
        found = [p for p in self.sensor.get_stream_profiles()
                 if p.stream_type() == stream and (index == 0 or p.stream_index() == index)]
        match = [p for p in found if (p.as_video_stream_profile().width(), p.as_video_stream_profile().height())
                 == (w, h)]
        if not match:
            sizes = sorted({f"{p.as_video_stream_profile().width()}x{p.as_video_stream_profile().height()}"
                            for p in found})
            raise DeviceError(f"{self.name}: holds no {stream.name} {index or ''} stream at {w}x{h} (it holds "
                              f"{', '.join(sizes) or 'none'}); set cameras[0].width/height to the recorded size")
        self.profile = match[0]
        self._frames: queue.Queue = queue.Queue(maxsize=1)
        self._closed = threading.Event()
        self.sensor.open(self.profile)
        self.sensor.start(self._take)

    def _take(self, frame) -> None:
        """The SDK's callback: hand the frame over, waiting until it is taken (or the stream is closed)."""
        units = frame.as_depth_frame().get_units() if frame.is_depth_frame() else None
        item = RecordedFrame(np.asanyarray(frame.get_data()).copy(), int(frame.get_frame_number()), units)
        while not self._closed.is_set():
            try:
                self._frames.put(item, timeout=0.05)
                return
            except queue.Full:
                pass

    def next_frame(self, timeout_s: float) -> RecordedFrame:
        """The next recorded frame; DeviceError once the recording has no more within ``timeout_s``."""
        try:
            return self._frames.get(timeout=timeout_s)
        except queue.Empty:
            raise DeviceError(f"{self.name}: the recording has no more frames (none within {timeout_s:g} s); record "
                              "a longer one or take fewer frames") from None

    def close(self) -> None:
        """Stop the playback (idempotent)."""
        if self._closed.is_set():
            return
        self._closed.set()
        try:
            self.sensor.stop()
            self.sensor.close()
        except RuntimeError:
            pass
