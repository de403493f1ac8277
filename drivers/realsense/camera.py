"""An Intel RealSense's infrared camera as the structured-light camera (``devices.camera.type`` ``"realsense"``).

A D400/D500 has two infrared imagers behind its IR-pass filters and a dot emitter between them. For coded light
the projector's own pattern is what the camera must see, so the emitter is switched off (``emitter_enabled``
0) and the left imager (``infrared`` 1, the frame the depth stream is given in) takes Y8 frames: (H, W) uint8.
Its intrinsics are the ones the SDK reports for that stream at the size taken.

The rig file's ``capture.camera`` controls, one option each, set and read back (a value the camera does not
keep is refused, never scanned with):

==========================  ===========================================================================
``exposure_us`` E           ``enable_auto_exposure`` 0, then ``exposure`` E (microseconds on a D4xx)
``exposure_us`` ``"auto"``  ``enable_auto_exposure`` 1 (coded light refuses it unless allowed)
``iso`` I                   ``gain`` 16 * I / 100 (a D4xx's unity gain is 16); ``"auto"``: left as it is
``fps``                     the stream's frame rate (an integer the camera offers: 6, 15, 30, 60, 90)
``white_balance_k``,        no such control on an infrared imager: not applied
``focus``
==========================  ===========================================================================

``devices.camera.bag`` plays a recording instead (``.bag``/``.db3``, :class:`~.recording.RecordingStream`): every
frame in order, none dropped, the controls those recorded (read back into :attr:`RealSenseCamera.read_back`, not set).

Device loss: a frame that does not come within ``frame_timeout_s`` is a DeviceTimeout while the camera is still
listed and a DeviceDisconnected once it is not; :meth:`RealSenseCamera.reconnect` searches for the same serial
number and starts the stream again with the controls in force (issue 34's contract, docs/hardware.md). A
recording that ends is a DeviceError: it does not come back.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.drivers.realsense.device import (CHECK_CABLE, device_serial, find_device, pinhole_from_intrinsics,
                                               read_option, set_option, stream_sensor)
from rangekit.drivers.realsense.recording import RecordingStream
from rangekit.drivers.retry import retry
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout, one_line
from rangekit.rig.camera_controls import CameraControls, require_locked
from rangekit.rig.checks import DEFAULT_SEARCH_S

__all__ = ["RealSenseCamera", "open_camera", "list_cameras", "UNITY_GAIN", "gain_for_iso"]

#: A D4xx's gain at ISO 100 (its smallest, unity).
UNITY_GAIN = 16.0
#: Timestamp domains whose frame times are on the host's clock (milliseconds since the epoch).
_HOST_DOMAINS = ("system_time", "global_time")


def gain_for_iso(iso: int) -> float:
    """The RealSense ``gain`` option of an ISO (100 = unity, :data:`UNITY_GAIN`)."""
    return UNITY_GAIN * float(iso) / 100.0


class RealSenseCamera:
    """A RealSense's infrared imager implementing :class:`rangekit.rig.devices.Camera` (module doc).

    Parameters
    ----------
    serial : serial number of the camera (None: the first found); ignored with ``bag``.
    bag : a recording to play instead of a camera.
    infrared : which imager, 1 (left, the depth stream's frame) or 2.
    size : (width, height) of the frames; the camera must offer it.
    controls : the rig file's ``capture.camera`` (None: ``CameraControls()``, locked at 33333 us, ISO 100, 30 fps).
    coded_light : refuse auto-exposure unless ``controls.allow_auto_exposure``.
    emitter : leave the dot emitter on (False for coded light: the projector's pattern alone).
    context : the ``rs.context`` to search (None: a new one); a test's software device lives in its own.

    Raises DeviceDisconnected when no camera with that serial answers within ``search_timeout_s``; DeviceError when
    the stream or a control cannot be set; ConfigError for auto-exposure with ``coded_light``; FileFormatError for
    a ``bag`` that is not a recording.
    """

    def __init__(self, serial: str | None = None, *, bag: str | Path | None = None, infrared: int = 1,
                 size: tuple[int, int] = (848, 480), controls: CameraControls | None = None,
                 coded_light: bool = False, emitter: bool = False, search_timeout_s: float = DEFAULT_SEARCH_S,
                 frame_timeout_s: float = 2.0, where: str = "RealSenseCamera", context=None) -> None:
        import pyrealsense2 as rs

        self._rs = rs
        self.controls = CameraControls() if controls is None else controls
        if coded_light:
            require_locked(self.controls, where=where)
        if float(self.controls.fps) != int(self.controls.fps):
            raise ConfigError(f"{where}: capture.camera.fps: a RealSense streams a whole number of frames a second "
                              f"(6, 15, 30, 60, 90), found {self.controls.fps:g}")
        self.serial, self.bag = serial, None if bag is None else Path(bag)
        self.infrared, self.size = int(infrared), (int(size[0]), int(size[1]))
        self.coded_light, self.emitter, self._where = coded_light, bool(emitter), where
        self.frame_timeout_s = float(frame_timeout_s)
        self._ctx = rs.context() if context is None else context
        self._pipeline = self._recording = None
        self.read_back: dict[str, float | None] = {}
        self.last_frame_time: float | None = None
        self._open(search_timeout_s)

    # ------------------------------------------------------------------ opening
    def _open(self, timeout_s: float) -> None:
        """Find the camera (or open the recording), start the infrared stream, apply the controls."""
        rs = self._rs
        if self.bag is not None:
            self._recording = RecordingStream(rs, self._ctx, self.bag, rs.stream.infrared, index=self.infrared,
                                              size=self.size)
            self.serial, self._name = self._recording.serial, self._recording.name
            self._started(self._recording.profile.as_video_stream_profile(), self._recording.sensor)
            return
        cfg = rs.config()
        device = find_device(rs, self._ctx, self.serial, timeout_s)
        self.serial = device_serial(rs, device)
        cfg.enable_device(self.serial)
        self._name = f"RealSense {self.serial}"
        (w, h), fps = self.size, int(self.controls.fps)
        cfg.enable_stream(rs.stream.infrared, self.infrared, w, h, rs.format.y8, fps)
        pipeline = rs.pipeline(self._ctx)
        try:
            profile = pipeline.start(cfg)
        except RuntimeError as exc:
            raise DeviceError(f"{self._name}: cannot stream infrared {self.infrared} at {w}x{h} Y8 {fps} fps "
                              f"({one_line(exc)}); it offers {self._offered(device)}: set cameras[0].width/height "
                              "and capture.camera.fps to one of them") from exc
        self._pipeline = pipeline
        stream = profile.get_stream(rs.stream.infrared, self.infrared).as_video_stream_profile()
        self._started(stream, stream_sensor(rs, profile.get_device(), rs.stream.infrared, self._name))

    def _started(self, stream, sensor) -> None:
        """The stream runs: its intrinsics, its sensor, the controls (the stream closed again on failure)."""
        try:
            self._camera = pinhole_from_intrinsics(self._rs, stream.get_intrinsics(), name=f"infrared {self.infrared}",
                                                   where=self._name)
            self._sensor = sensor
            self._apply(self.controls)
        except BaseException:
            self.close()
            raise

    def _offered(self, device) -> str:
        rs = self._rs
        if device is None:
            return "only the streams it recorded"
        found = sorted({f"{p.as_video_stream_profile().width()}x{p.as_video_stream_profile().height()} "
                        f"{p.fps()} fps" for s in device.query_sensors() for p in s.get_stream_profiles()
                        if p.stream_type() == rs.stream.infrared and p.format() == rs.format.y8})
        return ", ".join(found) or "no Y8 infrared stream"

    def _apply(self, controls: CameraControls) -> None:
        """Set the controls (module doc) and read them back into :attr:`read_back`; a recording's are only read."""
        rs, sensor, field = self._rs, self._sensor, "capture.camera"
        if self.bag is None:
            if controls.auto_exposure:
                set_option(rs, sensor, rs.option.enable_auto_exposure, 1, name=self._name,
                           field=f"{field}.exposure_us 'auto'")
            else:
                if sensor.supports(rs.option.enable_auto_exposure):
                    set_option(rs, sensor, rs.option.enable_auto_exposure, 0, name=self._name,
                               field=f"{field}.exposure_us (auto-exposure off)")
                set_option(rs, sensor, rs.option.exposure, float(controls.exposure_us), name=self._name,
                           field=f"{field}.exposure_us")
            if controls.iso is not None:
                set_option(rs, sensor, rs.option.gain, gain_for_iso(controls.iso), name=self._name,
                           field=f"{field}.iso {controls.iso}")
            if sensor.supports(rs.option.emitter_enabled):
                set_option(rs, sensor, rs.option.emitter_enabled, 1 if self.emitter else 0, name=self._name,
                           field="the dot emitter (off for coded light)")
        self.read_back = {name: read_option(rs, sensor, getattr(rs.option, name))
                          for name in ("enable_auto_exposure", "exposure", "gain", "emitter_enabled")}

    def reconnect(self, timeout_s: float) -> None:
        """Stop the stream and open the same camera again (its serial number), waiting up to ``timeout_s`` seconds
        for it to be listed and stream: after it was unplugged or reset. The controls in force are set again.

        Raises DeviceDisconnected if it is not back in time; DeviceError if it cannot stream again."""
        self.close()
        retry(self._open, timeout_s)

    # ------------------------------------------------------------------ Camera protocol
    @property
    def calibration(self) -> PinholeCamera:
        """The infrared imager at ``size`` as the SDK reports it; ``T_world_cam`` = I."""
        return self._camera

    def capture(self) -> np.ndarray:
        """One (H, W) uint8 infrared frame taken after this call started (frames already waiting are dropped;
        with host timestamps, so is one exposed before the call); a recording's next frame, none dropped. Raises
        DeviceTimeout / DeviceDisconnected (module doc)."""
        if self._recording is not None:
            self.last_frame_time = None
            return self._recording.next_frame(self.frame_timeout_s).data
        t0 = time.time() * 1000.0
        while self._pipeline.poll_for_frames():
            pass
        deadline = time.monotonic() + self.frame_timeout_s
        while True:
            frame = self._wait(max(0.001, deadline - time.monotonic())).get_infrared_frame(self.infrared)
            domain = frame.get_frame_timestamp_domain().name
            ts = frame.get_timestamp()
            if domain in _HOST_DOMAINS and ts < t0:
                continue
            self.last_frame_time = time.monotonic() - (time.time() - ts / 1000.0) if domain in _HOST_DOMAINS \
                else None
            return np.asanyarray(frame.get_data()).copy()

    def _wait(self, left_s: float):
        try:
            return self._pipeline.wait_for_frames(max(1, int(left_s * 1000)))
        except RuntimeError as exc:
            try:
                listed = self.serial in {device_serial(self._rs, d) for d in self._ctx.query_devices()}
            except RuntimeError:
                listed = False
            if not listed:
                raise DeviceDisconnected(f"{self._name}: lost while waiting for a frame ({one_line(exc)}); "
                                         f"{CHECK_CABLE}") from exc
            raise DeviceTimeout(f"{self._name}: no infrared frame within {self.frame_timeout_s:g} s "
                                f"({one_line(exc)}); {CHECK_CABLE}, and the frame rate") from exc

    def set_controls(self, controls: CameraControls) -> None:
        """Apply exposure and gain now, read back (the module doc's table). The frame rate is fixed while the stream
        runs: another ``fps`` raises DeviceError; auto-exposure for coded light raises ConfigError unless allowed."""
        if self.coded_light:
            require_locked(controls, where=self._where)
        if controls.fps != self.controls.fps:
            raise DeviceError(f"{self._name}: capture.camera.fps is set when the stream starts ({self.controls.fps:g}), "
                              f"found {controls.fps:g}; reopen the camera to change it")
        self._apply(controls)
        self.controls = controls

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Stop the stream (idempotent)."""
        recording, self._recording = self._recording, None
        if recording is not None:
            recording.close()
        pipeline, self._pipeline = self._pipeline, None
        if pipeline is not None:
            try:
                pipeline.stop()
            except RuntimeError:     # already stopped by the SDK (device gone)
                pass

    def __enter__(self) -> "RealSenseCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"RealSenseCamera({self.serial!r}, infrared={self.infrared}, size={self.size})"


def open_camera(sec: dict, rig, *, coded_light: bool, where: str, context=None) -> RealSenseCamera:
    """The RealSense infrared camera of a checked ``devices.camera`` section (:mod:`rangekit.drivers.cameras`);
    a relative ``bag`` is taken from the rig file's folder when ``where`` is its path."""
    from rangekit.rig.camera_controls import controls_from_capture

    bag = sec.get("bag")
    if bag is not None and not Path(bag).is_absolute() and Path(where).is_file():
        bag = Path(where).parent / bag
    return RealSenseCamera(sec.get("serial"), bag=bag, infrared=sec.get("infrared", 1),
                           size=(rig.camera.width, rig.camera.height),
                           controls=controls_from_capture(rig.capture, where=where), coded_light=coded_light,
                           search_timeout_s=sec.get("search_timeout_s", DEFAULT_SEARCH_S), where=where,
                           context=context)


def list_cameras(timeout_s: float = 1.0, context=None) -> list:
    """The RealSense cameras attached now (:mod:`rangekit.drivers.cameras`): serial number, name, firmware and USB
    type. The SDK lists them at once; ``timeout_s`` is not waited."""
    import pyrealsense2 as rs

    from rangekit.drivers.cameras import FoundCamera

    ctx = rs.context() if context is None else context
    out = []
    for d in ctx.query_devices():
        info = {k: d.get_info(getattr(rs.camera_info, k)) if d.supports(getattr(rs.camera_info, k)) else "-"
                for k in ("name", "firmware_version", "usb_type_descriptor")}
        out.append(FoundCamera(device_serial(rs, d), info["name"],
                               f"firmware {info['firmware_version']} USB {info['usb_type_descriptor']}"))
    return out
