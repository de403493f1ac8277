"""UVC webcams: frames through OpenCV's ``VideoCapture`` (its V4L2 backend), controls through the V4L2 ioctls
(:mod:`rangekit.drivers.uvc.v4l2`, :mod:`rangekit.drivers.uvc.controls`).

A UVC driver keeps a few frames queued (OpenCV's V4L2 backend asks for 4 buffers; when every buffer is full the
kernel drops the new frames, not the old): after a pattern change the first frames read were exposed before it.
:meth:`UvcCamera.capture` therefore discards ``flush_frames`` frames before the one it returns. ``rangekit check``
measures that number on the camera (the stale frames after a pattern change and the pattern delay) and writes it
into the rig file's ``devices.camera.flush_frames``.

The source is a device node (``/dev/video0``, a ``/dev/v4l/by-id/...`` link) or its index, or a recorded video
file: the same code reads both (open, size and format checked, frames flushed and converted), a recording without
controls. Frames are RGB uint8 (H, W, 3), grey (H, W) with ``"white_balance_k": "mono"``
(:func:`rangekit.image.to_grey`, rounded). OpenCV is imported here (it is a required dependency); linuxpy inside
the V4L2 layer, only when a device is opened.
"""

from __future__ import annotations

import os
import re
import stat
import time

import numpy as np

from rangekit.drivers.depthai.controls import check_frame_period
from rangekit.drivers.retry import retry
from rangekit.drivers.uvc.controls import apply_controls, verify
from rangekit.drivers.uvc.v4l2 import node_path, open_node
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout
from rangekit.rig.camera_controls import CameraControls, require_locked
from rangekit.rig.checks import DEFAULT_FLUSH_FRAMES, UVC_FORMATS

__all__ = ["UvcCamera", "open_camera", "list_cameras", "FOURCC"]

#: Each ``devices.camera.format`` (:data:`rangekit.rig.checks.UVC_FORMATS`) as the V4L2 fourcc asked of the webcam.
FOURCC = {"MJPEG": "MJPG", "YUYV": "YUYV"}
_CHECK = "check its USB cable and power (was it unplugged?)"


def _is_recording(path: str) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


class UvcCamera:
    """A UVC webcam (or a recorded video) implementing :class:`rangekit.rig.devices.Camera`.

    Parameters
    ----------
    source : int or str
        Device index N (``/dev/videoN``), a device node or link, or a video file (a recording: no controls).
    size : (width, height) of the frames; the webcam is asked for it and a different answer is refused.
    format : ``"MJPEG"`` or ``"YUYV"`` (:data:`FOURCC`), devices only.
    controls : CameraControls, optional
        Written and read back before the first frame (:mod:`rangekit.drivers.uvc.controls`); None: left as they are.
    coded_light : bool
        Opened for coded light: auto-exposure refused unless allowed, and a camera without an exposure control
        refused.
    flush_frames : frames discarded before each :meth:`capture` (the rig file's ``devices.camera.flush_frames``).
    calibration : PinholeCamera, optional
        The rig file's camera (a webcam has no calibration of its own).
    frame_timeout_s : how long a frame may take before the camera is reported silent.
    where : names the controls' origin (the rig file) in errors.
    """

    def __init__(self, source, *, size: tuple[int, int], format: str = "MJPEG", controls: CameraControls | None = None,
                 coded_light: bool = False, flush_frames: int = DEFAULT_FLUSH_FRAMES, calibration=None,
                 frame_timeout_s: float = 2.0, where: str = "UvcCamera") -> None:
        if format not in UVC_FORMATS:
            raise ConfigError(f"{where}: devices.camera.format: expected one of {', '.join(UVC_FORMATS)}, found "
                              f"{format!r}")
        self.path = node_path(source)
        self.recording = _is_recording(self.path)
        self.name = f"uvc {self.path}"
        self.size, self.format = (int(size[0]), int(size[1])), format
        self.controls, self.coded_light, self._where = controls, coded_light, where
        self.mono = bool(controls is not None and controls.mono)
        self.flush_frames, self.frame_timeout_s = int(flush_frames), float(frame_timeout_s)
        self._calibration = calibration
        self.limits: tuple[str, ...] = ()
        self.last_frame_time: float | None = None
        self.frames_read = 0
        self._cap = self._node = None
        if controls is not None:
            if coded_light:
                require_locked(controls, where=where)
            check_frame_period(controls, name=self.name)
        self._open()

    # ------------------------------------------------------------------ opening
    def _open(self) -> None:
        """Open the source, ask for the size, format and rate, apply the controls (closed again on failure)."""
        try:
            if self.recording or _is_recording(self.path):
                self._open_recording()
            else:
                self._open_device()
        except BaseException:
            self.close()
            raise

    def _open_recording(self) -> None:
        import cv2

        if not os.path.exists(self.path):
            raise DeviceDisconnected(f"{self.name}: the recording is gone")
        self._cap = self._video_capture(self.path, cv2.CAP_ANY)
        self._check_size()
        self.limits = ("a recording: no camera controls, frames in the order recorded",)

    def _open_device(self) -> None:
        import cv2

        self._node = open_node(self.path)        # one line when missing, not a device or not a capture node
        applied = None
        if self.controls is not None:            # written and read back before any frame
            applied = apply_controls(self._node, self.controls)
            self.limits = applied.limits
            if self.coded_light and any(line.startswith("exposure") for line in applied.limits):
                raise DeviceError(f"{self.name}: {applied.limits[0]}; coded light needs a locked exposure: use "
                                  "another camera")
        real = os.path.realpath(self.path)
        match = re.fullmatch(r"/dev/video(\d+)", real)
        self._cap = self._video_capture(int(match.group(1)) if match else real, cv2.CAP_V4L2)
        cap = self._cap
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*FOURCC[self.format]))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.size[0])
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.size[1])
        fps = CameraControls().fps if self.controls is None else self.controls.fps
        cap.set(cv2.CAP_PROP_FPS, fps)
        cap.set(cv2.CAP_PROP_READ_TIMEOUT_MSEC, self.frame_timeout_s * 1e3)
        self._check_size()
        fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode("latin-1")
        if fourcc != FOURCC[self.format]:
            raise DeviceError(f"{self.name}: asked for {self.format} frames, the camera gives {fourcc!r}; set "
                              f"devices.camera.format to one it has (`v4l2-ctl -d {self.path} --list-formats-ext`)")
        got_fps = cap.get(cv2.CAP_PROP_FPS)
        if got_fps > 0 and abs(got_fps - fps) > 0.01 * fps:
            raise DeviceError(f"{self.name}: asked for capture.camera.fps {fps:g}, the camera runs at {got_fps:g} at "
                              f"{self.size[0]}x{self.size[1]} {self.format}; set capture.camera.fps to {got_fps:g}")
        if applied is not None:                  # a webcam may reset its controls when its stream starts
            self._grab()
            verify(self._node, applied, when=" after its stream started")

    def _video_capture(self, source, api):
        import cv2

        cap = cv2.VideoCapture(source, api)
        if not cap.isOpened():
            cap.release()
            raise DeviceError(f"{self.name}: OpenCV could not open it for frames (is another program using the "
                              "camera?)")
        return cap

    def _check_size(self) -> None:
        import cv2

        got = (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if got != self.size:
            what = "the recording's frames are" if self.recording else f"asked for {self.size[0]}x{self.size[1]}, " \
                                                                       "the camera gives"
            raise DeviceError(f"{self.name}: {what} {got[0]}x{got[1]}; set cameras[0].width and height to a size "
                              "it has" + ("" if self.recording else
                                          f" (`v4l2-ctl -d {self.path} --list-formats-ext`)"))

    def reconnect(self, timeout_s: float) -> None:
        """Release the camera and open it again (the same node), waiting up to ``timeout_s`` seconds for it to come
        back after it was unplugged; the controls in force are written and read back again before the first frame.

        Raises DeviceDisconnected if it is not back in time; DeviceError if it is back but cannot be opened."""
        self.close()
        retry(lambda _left: self._open(), timeout_s)

    # ------------------------------------------------------------------ Camera protocol
    @property
    def calibration(self):
        """The rig file's camera (a webcam has no calibration of its own)."""
        if self._calibration is None:
            raise DeviceError(f"{self.name}: no calibration: give the rig file's camera (calibration=rig.camera)")
        return self._calibration

    def capture(self) -> np.ndarray:
        """One frame taken after the call: the ``flush_frames`` frames queued before it are read and dropped.
        (H, W, 3) RGB uint8, or (H, W) with mono controls."""
        for _ in range(self.flush_frames):
            self._grab()
        return self.unflushed_frame()

    def unflushed_frame(self) -> np.ndarray:
        """The next frame of the driver's queue, nothing dropped (``rangekit check`` counts the stale ones)."""
        import cv2

        self._grab()
        ok, frame = self._cap.retrieve()
        if not ok or frame is None:
            raise self._lost("decoding a frame")
        if frame.shape[:2] != (self.size[1], self.size[0]):
            raise DeviceError(f"{self.name}: a frame of {frame.shape[1]}x{frame.shape[0]}, expected "
                              f"{self.size[0]}x{self.size[1]}")
        rgb = cv2.cvtColor(frame, cv2.COLOR_BGR2RGB) if frame.ndim == 3 else frame
        if self.mono and rgb.ndim == 3:
            from rangekit.image import to_grey

            return np.round(to_grey(rgb)).astype(np.uint8)
        return rgb

    def _grab(self) -> None:
        if self._cap is None:
            raise DeviceDisconnected(f"{self.name}: not open (closed, or lost and not back); {_CHECK}")
        if not self._cap.grab():
            raise self._lost("reading a frame")
        self.frames_read += 1
        self.last_frame_time = time.monotonic()

    def _lost(self, what: str) -> DeviceError:
        """The error of a failed read: the node gone (DeviceDisconnected), a recording's end, or silence
        (DeviceTimeout)."""
        if not os.path.exists(self.path):
            return DeviceDisconnected(f"{self.name}: lost while {what} (the device node is gone); {_CHECK}")
        if self.recording:
            return DeviceError(f"{self.name}: the recording ended after {self.frames_read} frames")
        return DeviceTimeout(f"{self.name}: no frame within {self.frame_timeout_s:g} s while {what}; {_CHECK}, and "
                             "that no other program holds the camera")

    def set_controls(self, controls: CameraControls) -> None:
        """Write ``controls`` now and read them back (:func:`rangekit.drivers.uvc.controls.apply_controls`). The
        frame rate and mono/colour are fixed when the camera is opened; a different ``fps`` or ``mono`` is refused."""
        if self.coded_light:
            require_locked(controls, where=self._where)
        check_frame_period(controls, name=self.name)
        now = self.controls or CameraControls(fps=controls.fps, mono=self.mono)
        for field in ("fps", "mono"):
            if getattr(controls, field) != getattr(now, field):
                raise DeviceError(f"{self.name}: capture.camera.{field} is set when the camera is opened "
                                  f"({getattr(now, field)!r}), found {getattr(controls, field)!r}; reopen the camera")
        if self._node is not None:
            self.limits = apply_controls(self._node, controls).limits
        self.controls = controls

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Release the frames and the control node (idempotent)."""
        cap, self._cap = self._cap, None
        node, self._node = self._node, None
        if cap is not None:
            cap.release()
        if node is not None:
            node.close()

    def __enter__(self) -> "UvcCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"UvcCamera({self.path!r}, size={self.size}, format={self.format!r}, flush_frames={self.flush_frames})"


def open_camera(sec: dict, rig, *, coded_light: bool, where: str) -> UvcCamera:
    """The webcam of a checked ``devices.camera`` section (:mod:`rangekit.drivers.cameras`)."""
    from rangekit.rig.camera_controls import controls_from_capture

    return UvcCamera(sec.get("device", 0), size=(rig.camera.width, rig.camera.height),
                     format=sec.get("format", "MJPEG"), controls=controls_from_capture(rig.capture, where=where),
                     coded_light=coded_light, flush_frames=sec.get("flush_frames", DEFAULT_FLUSH_FRAMES),
                     calibration=rig.camera, where=where)


def list_cameras(timeout_s: float = 1.0) -> list:
    """The V4L2 video capture nodes present (:mod:`rangekit.drivers.cameras`); a webcam's metadata node is left
    out. ``timeout_s`` is not needed: the nodes are there or not."""
    from rangekit.drivers.cameras import FoundCamera
    from rangekit.drivers.uvc.v4l2 import capture_nodes

    by_id = {}
    for link in sorted(os.listdir("/dev/v4l/by-id")) if os.path.isdir("/dev/v4l/by-id") else []:
        by_id.setdefault(os.path.realpath(os.path.join("/dev/v4l/by-id", link)), os.path.join("/dev/v4l/by-id", link))
    found = []
    for node in capture_nodes():
        try:
            link = by_id.get(os.path.realpath(node.path))
            found.append(FoundCamera(node.path, node.card, f"{node.driver} {node.bus_info}"
                                     + (f" (stable name {link})" if link else "")))
        finally:
            node.close()
    return found
