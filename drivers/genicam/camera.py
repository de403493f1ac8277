"""A GenICam/GenTL camera as the camera of a rig (:class:`rangekit.rig.devices.Camera`), through harvesters.

:class:`GenicamCamera` opens the device a ``devices.camera`` section names on its producer
(:mod:`rangekit.drivers.genicam.producer`), writes the pixel format, the rig camera's size, the rig file's
``capture.camera`` controls and the trigger, every value read back (:mod:`rangekit.drivers.genicam.nodes`), and
streams into :data:`BUFFERS` buffers.

**No stale frame.** :meth:`GenicamCamera.capture` returns a frame exposed after it was called: acquisition calls it
``capture.pattern_delay_s`` after showing a pattern (the projector's latency, ``rangekit check`` measures it). It
first returns every filled buffer to the camera (the flush), then:

- software trigger (``trigger_source`` ``"Software"``): fires ``TriggerSoftware`` and takes that frame, which is
  exposed after the call by construction;
- free-running, or a hardware trigger on a line (the projector's VSYNC): drops ``flush_frames`` frames (default
  :data:`FLUSH_FRAMES`: the frame being exposed, and the next one that a camera exposing while it reads out may have
  started already) and takes the next.

:meth:`GenicamCamera.next_frame` takes the frames in the camera's order instead (no flush); ``last_frame_id`` is
the GenTL frame id of the frame returned last, ``last_frame_time`` the host's ``time.monotonic()`` when it arrived.

**A device that goes away** (unplugged, its producer or device closed): a GenTL error while waiting for a frame is a
:class:`DeviceDisconnected` ("lost while waiting for a frame (...); check ..."); no frame within the frame timeout a
:class:`DeviceTimeout`. :meth:`GenicamCamera.reconnect` (issue 34's contract, docs/hardware.md "Devices that go away
mid-scan") releases everything, searches for the same serial number until ``timeout_s`` and opens it again with the
settings in force.
"""

from __future__ import annotations

import time

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.drivers.depthai.controls import check_frame_period
from rangekit.drivers.genicam.frames import frame_from_buffer
from rangekit.drivers.genicam.nodes import apply_controls, apply_format, apply_trigger, find_node
from rangekit.drivers.genicam.producer import describe, producer_files, search_device
from rangekit.drivers.retry import retry
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout, one_line
from rangekit.progress import LOGGER
from rangekit.rig.camera_controls import CameraControls, require_locked
from rangekit.rig.checks import DEFAULT_SEARCH_S

__all__ = ["GenicamCamera", "open_camera", "list_cameras", "BUFFERS", "FLUSH_FRAMES"]

#: Buffers announced to the producer: 16 frames of slack (0.16 s at 100 fps) before a slow reader drops one.
BUFFERS = 16
#: Frames dropped after the flush when not software-triggered (module docstring).
FLUSH_FRAMES = 2
#: What a lost or silent camera's message says to check.
_CHECK = "check its cable (USB3/GigE) and power (was it unplugged or reset?)"


class GenicamCamera:
    """A GenICam camera implementing :class:`rangekit.rig.devices.Camera`.

    Parameters
    ----------
    producers : the GenTL producer files (:func:`rangekit.drivers.genicam.producer.producer_files`).
    serial, user_id : the device's serial number or user id; the first device found when both are None.
    pixel_format : one of :data:`rangekit.drivers.genicam.frames.PIXEL_FORMATS`, set before streaming.
    size : (width, height) of the frames, the rig's ``cameras[0]`` size; written to ``Width``/``Height``.
    controls : the rig file's ``capture.camera``; None: the defaults (every control locked).
    coded_light : refuse auto-exposure unless ``controls.allow_auto_exposure`` (ConfigError).
    trigger_source : None (free-running), ``"Software"`` or a line (``"Line1"``); ``trigger_activation`` its edge.
    flush_frames : frames dropped after the flush when not software-triggered (module docstring).
    calibration : the rig's camera (what :attr:`calibration` returns).
    search_timeout_s : how long to look for the device; ``frame_timeout_s`` how long to wait for a frame.

    Raises DeviceError for a bad producer, a refused setting or a pixel format the device lacks (one line naming the
    device and the node), DeviceDisconnected when the device is not found.
    """

    def __init__(self, producers: tuple[str, ...], *, serial: str | None = None, user_id: str | None = None,
                 pixel_format: str = "Mono8", size: tuple[int, int] = (400, 400), controls: CameraControls | None = None,
                 coded_light: bool = False, trigger_source: str | None = None, trigger_activation: str = "RisingEdge",
                 flush_frames: int = FLUSH_FRAMES, calibration: PinholeCamera | None = None,
                 search_timeout_s: float = DEFAULT_SEARCH_S, frame_timeout_s: float = 2.0,
                 where: str = "GenicamCamera") -> None:
        self.producers = tuple(producers)
        self.serial, self.user_id = serial, user_id
        self.pixel_format, self.size = pixel_format, (int(size[0]), int(size[1]))
        self.controls = CameraControls() if controls is None else controls
        self.coded_light, self._where = coded_light, where
        self.trigger_source, self.trigger_activation = trigger_source, trigger_activation
        self.flush_frames = int(flush_frames)
        self._calibration = calibration
        self.frame_timeout_s = float(frame_timeout_s)
        if coded_light:
            require_locked(self.controls, where=where)
        check_frame_period(self.controls, name=where)
        self.harvester = self._acquirer = None
        self.triggered, self._warned = False, False
        self.limits: tuple[str, ...] = ()
        self.last_frame_id: int | None = None
        self.last_frame_time: float | None = None
        self.name = f"genicam camera {serial or user_id or '(first found)'}"
        self._open(search_timeout_s)

    # ------------------------------------------------------------------ opening
    def _open(self, timeout_s: float) -> None:
        """Find the device, write every setting and start streaming (released again on failure)."""
        self.harvester, entry = search_device(self.producers, self.serial, self.user_id, timeout_s, where=self._where)
        self.serial = entry.serial if self.serial is None and self.user_id is None else self.serial
        self.name, self.device = f"genicam camera {describe(entry)}", entry
        try:
            self._acquirer = self.harvester.create(entry.index)
            nm = self._acquirer.remote_device.node_map
            limits = apply_format(nm, self.pixel_format, self.size, device=self.name)
            limits += apply_controls(nm, self.controls, device=self.name)
            self.triggered, more = apply_trigger(nm, self.trigger_source, self.trigger_activation, device=self.name)
            self.limits = tuple(limits + more)
            self._acquirer.num_buffers = BUFFERS
            self._acquirer.start()
        except Exception as exc:
            self.close()
            if isinstance(exc, (DeviceError, ConfigError)):
                raise
            raise DeviceError(f"{self.name}: could not start streaming ({one_line(exc)}); check that no other "
                              f"program holds it, and {_CHECK.removeprefix('check ')}") from None
        if not self._warned:        # once: a reconnect meets the same limits
            for line in self.limits:
                LOGGER.warning("%s: limit of the device: %s", self.name, line)
            self._warned = True

    def reconnect(self, timeout_s: float) -> None:
        """Release the device and its producer and open them again (the same serial number), waiting up to
        ``timeout_s`` seconds for it to be listed: after it was unplugged or reset mid-scan. The settings in force
        are written again. DeviceDisconnected when it is not back in time."""
        self.close()
        retry(self._open, timeout_s)

    @property
    def acquirer(self):
        """harvesters' ``ImageAcquirer`` of the device (None when closed), for what rangekit does not wrap."""
        return self._acquirer

    @property
    def node_map(self):
        """The device's GenICam node map (genicam.genapi), for what rangekit does not set; DeviceDisconnected when
        closed."""
        return self._node_map()

    # ------------------------------------------------------------------ Camera protocol
    @property
    def calibration(self) -> PinholeCamera:
        """The rig's camera (a GenICam device keeps no calibration)."""
        if self._calibration is None:
            raise ConfigError(f"{self.name}: no calibration; open it with the rig's camera (open_camera)")
        return self._calibration

    def capture(self) -> np.ndarray:
        """One frame exposed after this call (module docstring): (H, W) grey or (H, W, 3) RGB, uint8 or uint16.

        Raises DeviceTimeout when no frame comes within ``frame_timeout_s``, DeviceDisconnected when the device is
        lost."""
        self._flush()
        if self.triggered and self.trigger_source == "Software":
            self._execute("TriggerSoftware")
        else:
            for _ in range(self.flush_frames):
                self._fetch().queue()
        return self.next_frame()

    def next_frame(self) -> np.ndarray:
        """The camera's next frame in order (no flush); ``last_frame_id`` and ``last_frame_time`` are its."""
        buffer = self._fetch()
        try:
            frame, _ = frame_from_buffer(buffer, grey=self.controls.mono)
            self.last_frame_id = int(buffer.module.frame_id)
        except DeviceError as exc:
            raise DeviceError(f"{self.name}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - a GenTL error reading the buffer: the device went away
            raise DeviceDisconnected(f"{self.name}: lost while reading a frame ({one_line(exc)}); {_CHECK}") from None
        finally:
            self._requeue(buffer)
        return frame

    def set_controls(self, controls: CameraControls) -> None:
        """Write exposure, gain and white balance now, read back (frames already exposed keep the old ones). The
        frame rate and mono/colour are set when the camera is opened: another ``fps`` or ``mono`` is refused."""
        if self.coded_light:
            require_locked(controls, where=self._where)
        for field in ("fps", "mono"):
            if getattr(controls, field) != getattr(self.controls, field):
                raise DeviceError(f"{self.name}: capture.camera.{field} is set when the camera is opened "
                                  f"({getattr(self.controls, field)!r}), found {getattr(controls, field)!r}; reopen "
                                  "the camera to change it")
        check_frame_period(controls, name=self.name)
        nm = self._node_map()
        try:
            apply_controls(nm, controls, device=self.name)
        except DeviceError:
            raise
        except Exception as exc:  # noqa: BLE001 - a GenTL error writing a node: the device went away
            raise DeviceDisconnected(f"{self.name}: could not write the controls ({one_line(exc)}); {_CHECK}") from None
        self.controls = controls

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Stop streaming and release the device and the producer (idempotent; a device already gone is quiet)."""
        acquirer, self._acquirer = self._acquirer, None
        harvester, self.harvester = self.harvester, None
        for obj, release in ((acquirer, "destroy"), (harvester, "reset")):
            if obj is None:
                continue
            try:
                getattr(obj, release)()
            except Exception:  # noqa: BLE001 - the device or producer is gone already: nothing left to release
                finalizer = getattr(obj, "_finalizer", None)    # harvesters would try again at exit, loudly
                if finalizer is not None:
                    finalizer.detach()

    def __enter__(self) -> "GenicamCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"GenicamCamera({self.name!r}, {self.pixel_format}, size={self.size})"

    # ------------------------------------------------------------------ helpers
    def _node_map(self):
        if self._acquirer is None:
            raise DeviceDisconnected(f"{self.name}: closed (the device was lost or released); {_CHECK}")
        return self._acquirer.remote_device.node_map

    def _execute(self, command: str) -> None:
        _, node = find_node(self._node_map(), (command,))
        try:
            node.execute()
        except Exception as exc:  # noqa: BLE001 - a GenTL error: the device went away
            raise DeviceDisconnected(f"{self.name}: {command} failed ({one_line(exc)}); {_CHECK}") from None

    def _fetch(self):
        """The next filled buffer, within ``frame_timeout_s``."""
        if self._acquirer is None:
            self._node_map()
        try:
            buffer = self._acquirer.try_fetch(timeout=self.frame_timeout_s)
        except Exception as exc:  # noqa: BLE001 - genicam's GenTL exceptions: the producer or device went away
            raise DeviceDisconnected(f"{self.name}: lost while waiting for a frame ({one_line(exc)}); "
                                     f"{_CHECK}") from None
        if buffer is None:
            trigger = f"; the trigger source {self.trigger_source} gets no pulses?" if self.triggered else ""
            raise DeviceTimeout(f"{self.name}: no frame within {self.frame_timeout_s:g} s; {_CHECK}, and the frame "
                                f"rate{trigger}")
        self.last_frame_time = time.monotonic()
        return buffer

    def _requeue(self, buffer) -> None:
        try:
            buffer.queue()
        except Exception as exc:  # noqa: BLE001 - the device went away with the buffer
            raise DeviceDisconnected(f"{self.name}: lost while returning a buffer ({one_line(exc)}); {_CHECK}") \
                from None

    def _flush(self) -> None:
        """Every filled buffer back to the camera unread (polled for 1 ms each)."""
        acquirer = self._acquirer
        if acquirer is None:
            self._node_map()
        while True:
            try:
                buffer = acquirer.try_fetch(timeout=1e-3)
            except Exception as exc:  # noqa: BLE001 - as in _fetch
                raise DeviceDisconnected(f"{self.name}: lost while flushing its buffers ({one_line(exc)}); "
                                         f"{_CHECK}") from None
            if buffer is None:
                return
            self._requeue(buffer)


def open_camera(sec: dict, rig, *, coded_light: bool, where: str) -> GenicamCamera:
    """The GenICam camera of a checked ``devices.camera`` section (:mod:`rangekit.drivers.cameras`)."""
    from rangekit.rig.camera_controls import controls_from_capture

    cam = rig.camera
    controls = controls_from_capture(rig.capture, where=where)
    fmt = sec.get("pixel_format", "Mono8")
    bits = int("".join(c for c in fmt if c.isdigit()) or 8)
    if bits in (10, 12) and rig.capture.get("bits") != bits:
        raise ConfigError(f"{where}: capture.bits: devices.camera.pixel_format {fmt} gives {bits}-bit values, found "
                          f"{rig.capture.get('bits')!r}; set capture.bits to {bits} (decoding takes 2**bits - 1 as "
                          "full scale)")
    frame_timeout = max(2.0, 3.0 * (sec.get("flush_frames", FLUSH_FRAMES) + 1) / controls.fps)
    return GenicamCamera(producer_files(sec.get("producer"), where=where), serial=sec.get("serial"),
                         user_id=sec.get("user_id"), pixel_format=sec.get("pixel_format", "Mono8"),
                         size=(cam.width, cam.height), controls=controls, coded_light=coded_light,
                         trigger_source=sec.get("trigger_source"),
                         trigger_activation=sec.get("trigger_activation", "RisingEdge"),
                         flush_frames=sec.get("flush_frames", FLUSH_FRAMES), calibration=cam,
                         search_timeout_s=sec.get("search_timeout_s", DEFAULT_SEARCH_S), frame_timeout_s=frame_timeout,
                         where=where)


def list_cameras(timeout_s: float = 1.0) -> list:
    """The GenICam cameras the producers of ``GENICAM_GENTL64_PATH`` list (:mod:`rangekit.drivers.cameras`); [] when
    it names none. A producer that is not one raises its one-line DeviceError."""
    import os

    from rangekit.drivers.cameras import FoundCamera
    from rangekit.drivers.genicam.producer import GENTL_ENV, device_entries, open_harvester

    if not os.environ.get(GENTL_ENV, "").strip():
        return []
    files = producer_files(None, where=GENTL_ENV)
    harvester = open_harvester(files)
    try:
        return [FoundCamera(e.serial or "?", f"{e.vendor} {e.model}",
                            f"id {e.id}" + (f", user id {e.user_id}" if e.user_id else "")) for e in
                device_entries(harvester)]
    finally:
        harvester.reset()
