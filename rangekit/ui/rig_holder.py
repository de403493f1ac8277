"""The rig the web app shows: the simulator's (``--rig sim``) or a rig file's devices, opened once, used by one
caller at a time.

The Live page grabs frames, shows test patterns and jogs the turntable through it; a long job (a scan, a
calibration) takes the whole rig with :meth:`RigHolder.hold` and the live stream waits meanwhile. Every device
call is made under one lock, so two browsers cannot interleave a pattern and a frame.

Every change of what :meth:`RigHolder.status` shows (a pattern, a jog, a job taking or freeing the rig, the rig
file written, the devices opened) calls :attr:`RigHolder.on_change`: the app says it on its notifier
(:mod:`rangekit.ui.jobs.notifier`), and the pages are sent the status again over ``/ws/jobs``.
"""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager

from dataclasses import replace
from pathlib import Path

import numpy as np

from rangekit.errors import RangekitError
from rangekit.rig.camera_controls import CONTROL_FIELDS, CameraControls, controls_from_capture
from rangekit.rig.rig_edits import write_capture_fields
from rangekit.rig.rig_file import load_rig, save_rig

__all__ = ["PATTERNS", "RigHolder", "test_pattern"]

#: The projector test patterns the Live page offers ("gray3": the Gray code's bit 3 of the column, ...).
PATTERNS = ("white", "black", "checker") + tuple(f"gray{k}" for k in range(10))


def test_pattern(name: str, width: int, height: int) -> np.ndarray:
    """(height, width) uint8 projector image of test pattern ``name`` (:data:`PATTERNS`): all 255, all 0, a
    checkerboard of 32-pixel squares, or bit ``k`` of the Gray code of each column (``gray<k>``)."""
    if name == "white":
        return np.full((height, width), 255, np.uint8)
    if name == "black":
        return np.zeros((height, width), np.uint8)
    if name == "checker":
        r, c = np.indices((height, width))
        return (((r // 32) + (c // 32)) % 2 * 255).astype(np.uint8)
    if name.startswith("gray") and name[4:].isdigit() and name in PATTERNS:
        col = np.arange(width)
        bit = ((col ^ (col >> 1)) >> int(name[4:])) & 1
        return np.broadcast_to((bit * 255).astype(np.uint8), (height, width)).copy()
    raise RangekitError(f"pattern {name!r}: unknown; expected one of {', '.join(PATTERNS)}")


class _NoDevices:
    """A hardware rig whose devices are not open (they failed to, or a scan child holds them)."""

    camera = projector = turntable = None

    def close(self) -> None:
        pass


class RigHolder:
    """The open rig: ``devices`` (a :class:`rangekit.sim.SimRig` or the drivers' ``HardwareRig``: ``camera``,
    ``projector``, ``turntable``), its :class:`rangekit.rig.rig_file.Rig` and where it came from."""

    def __init__(self, devices, rig, source: str, full_scale: float, rig_file: Path) -> None:
        self.devices, self.rig, self.source, self.full_scale = devices, rig, source, float(full_scale)
        self.rig_file = Path(rig_file)
        self._lock = threading.RLock()
        self.pattern = "white"
        self.last_reply, self.fault = "opened", None
        self.busy: str | None = None       # what holds the rig (a scan, a calibration), None: free
        self._live_while_busy = False      # the job holding the rig lets the stream grab (between its captures)
        self._closers: list = []
        self._angle_deg: float | None = None   # the turntable's angle as last read (degrees)
        self.turning = False                   # a jog under way (the status shows the last angle meanwhile)
        self.on_change = None                  # called (no argument) whenever the status changes
        self._show(self.pattern)

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()

    @classmethod
    def simulated(cls, rig_file: Path, obj: str = "lumpy") -> "RigHolder":
        """The simulated rig with ``obj`` on its turntable, its rig file ``rig_file`` (the default rig's, written
        there when missing; read, checked and used when present: its camera controls drive the simulated
        camera)."""
        from rangekit.sim import SimRig, default_rig, default_scene

        rig_file = Path(rig_file)
        if not rig_file.exists():
            save_rig(default_rig(), rig_file)
        rig = load_rig(rig_file)
        # The simulator's geometry is always its own truth; the rig file may hold a calibration of it.
        sim = SimRig(default_scene(obj), default_rig())
        sim.camera.set_controls(controls_from_capture(rig.capture, where=str(rig_file)))
        # The turntable as on hardware: rangekit's Horus driver talking bytes over a pty to the simulated board,
        # which turns in real time (30 deg/s); the simulated camera sees the angle the board reports.
        from rangekit.drivers.turntable import HorusTurntable
        from rangekit.sim.devices.firmware import start_firmware

        firmware = start_firmware("horus", time_scale=1.0)
        sim.turntable = HorusTurntable(firmware.port)
        holder = cls(sim, rig, "simulator", float(sim.imaging.max_value), rig_file)
        holder._closers += [sim.turntable.close, firmware.stop]
        holder._read_angle()     # shown from the start, even while the live stream keeps the lock busy
        holder.last_reply = f"opened; turntable: Horus firmware on {firmware.port}"
        return holder

    @classmethod
    def hardware(cls, rig_file: Path) -> "RigHolder":
        """The devices a hardware rig file names (:func:`rangekit.drivers.open_rig_devices`). The rig file is checked
        first: a bad field is its one-line error, raised before the server starts. A device that does not open
        (unplugged, held by another program) is not: the app starts, the page shows the driver's one-line error
        as the rig's fault, and :meth:`connect` tries again."""
        from rangekit.rig.checks import validate_rig_for_hardware

        rig_file = Path(rig_file)
        rig = load_rig(rig_file)
        validate_rig_for_hardware(rig, where=str(rig_file))
        bits = rig.capture.get("bits")
        holder = cls(_NoDevices(), rig, "hardware", float((1 << int(bits)) - 1) if bits else 255.0, rig_file)
        holder.connect()
        return holder

    def connect(self) -> dict:
        """Hardware: (re)open the rig file's devices; their failure is kept as the fault. The status."""
        from rangekit.drivers import open_rig_devices

        with self._lock:
            self._refuse_if_busy()
            if self.simulated_rig:
                raise RangekitError("the simulated rig is always connected")
            self.close()
            try:
                self.devices = open_rig_devices(self.rig, where=str(self.rig_file))
            except RangekitError as exc:
                self.devices, self.fault, self.last_reply = _NoDevices(), str(exc), "not connected"
                self._changed()
                return self.status()
            self._closers = [self.devices.close]
            self.fault, self.last_reply = None, "opened"
            self._read_angle()     # shown from the start, even while the live stream keeps the lock busy
            self._show(self.pattern)
            self._changed()
            return self.status()

    def release(self, what: str) -> None:
        """Hardware: close the devices for another process (a scan child) and mark the rig busy with ``what``."""
        with self._lock:
            self._refuse_if_busy()
            self.busy = what
            self.close()
            self.devices = _NoDevices()
        self._changed()

    def reacquire(self) -> None:
        """After :meth:`release`: free the rig and open its devices again."""
        with self._lock:
            self.busy = None
        self.connect()

    def close(self) -> None:
        """Close the devices (the turntable's serial port, the simulated board)."""
        with self._lock:
            for close in self._closers:
                try:
                    close()
                except Exception:  # noqa: BLE001 - closing at the end: nothing left to tell
                    pass
            self._closers = []

    @property
    def simulated_rig(self) -> bool:
        """Whether the devices are the simulator's (the app may move a board, knows the truth)."""
        return hasattr(self.devices, "set_scene")

    @contextmanager
    def locked(self):
        """The devices, with no other call of this holder's under way (a job moving the simulated board)."""
        with self._lock:
            yield self.devices

    def allow_live(self, allowed: bool) -> None:
        """While a job holds the rig: let the live stream grab frames (a calibration while the board is placed)
        or not; returns once no frame is being grabbed."""
        with self._lock:
            self._live_while_busy = bool(allowed)

    def replace_rig(self, rig) -> None:
        """Write ``rig`` (a calibration's result) as the rig file, atomically, and use it from now on."""
        with self._lock:
            save_rig(rig, self.rig_file)
            self.rig = rig
            self.last_reply = f"rig file: {self.rig_file.name} written (calibrated)"
        self._changed()

    def set_camera(self, changes: dict) -> dict:
        """Write the ``capture.camera`` fields of ``changes`` into the rig file (atomically, checked first: a bad
        value is the rig file's one-line error and nothing is written) and apply them to the camera; the
        controls as written."""
        return self.apply_capture({}, changes)

    def apply_capture(self, fields: dict, camera: dict) -> dict:
        """Write ``capture.<name>`` of ``fields`` and ``capture.camera.<name>`` of ``camera`` into the rig file
        (checked first, then atomically) and apply the camera's controls; ``capture.camera`` as written."""
        with self._lock:
            self._refuse_if_busy()
            rig = write_capture_fields(self.rig_file, fields, camera=camera)
            if hasattr(self.devices.camera, "set_controls"):
                self.devices.camera.set_controls(controls_from_capture(rig.capture, where=str(self.rig_file)))
            self.rig = replace(self.rig, capture={**self.rig.capture, **rig.capture})
            self.last_reply = "rig file: " + ", ".join([*(f"capture.{k} {v}" for k, v in fields.items()),
                                                        *(f"capture.camera.{k} {v}" for k, v in camera.items())])
        self._changed()
        return dict(rig.capture.get("camera", {}))

    @contextmanager
    def hold(self, what: str):
        """The rig for one job (``what`` says which, shown as the device status); refused while another holds it."""
        with self._lock:
            if self.busy is not None:
                raise RangekitError(f"the rig is busy: {self.busy}; wait for it to finish")
            self.busy = what
        self._changed()
        try:
            yield self.devices
        finally:
            with self._lock:
                self.busy, self._live_while_busy = None, False
            self._changed()

    def grab(self) -> np.ndarray | None:
        """One camera frame with the current pattern, or None while a job holds the rig."""
        with self._lock:
            if self.busy is not None and not self._live_while_busy:
                return None
            if self.devices.camera is None:
                raise RangekitError(f"not connected: {self.fault}" if self.fault else "no camera in this rig")
            try:
                image = self.devices.camera.capture()
            except RangekitError as exc:
                if self.fault != str(exc):
                    self.fault = str(exc)
                    self._changed()
                raise
            if self.fault is not None:
                self.fault = None
                self._changed()
            return image

    def _show(self, name: str) -> None:
        proj = self.devices.projector
        if proj is None:
            return
        w, h = proj.resolution
        proj.show(test_pattern(name, w, h))

    def show_pattern(self, name: str) -> None:
        """Project test pattern ``name``."""
        with self._lock:
            self._refuse_if_busy()
            test_pattern(name, 1, 1)      # the name checked before any device call
            if self.devices.projector is None:
                raise RangekitError(f"not connected: {self.fault}" if self.fault else "this rig has no projector")
            self._show(name)
            self.pattern = name
            self.last_reply = f"pattern {name} shown"
        self._changed()

    def turn(self, *, degrees: float | None = None, home: bool = False) -> float:
        """Jog the turntable by ``degrees`` or send it home (0 degrees); returns its angle in degrees."""
        with self._lock:
            self._refuse_if_busy()
            table = self.devices.turntable
            if table is None:
                raise RangekitError(f"not connected: {self.fault}" if self.fault else "this rig has no turntable")
            target = 0.0 if home else float(np.degrees(table.angle)) + float(degrees)
            started = time.perf_counter()
            self.turning, self.last_reply = True, f"turntable turning to {target:.2f} deg"
            self._changed()
            try:
                table.rotate_to(np.radians(target))
            finally:
                self.turning = False
                self._changed()
            self._angle_deg = round(float(np.degrees(table.angle)), 3)
            self.last_reply = f"turntable at {self._angle_deg:.2f} deg ({time.perf_counter() - started:.2f} s)"
        self._changed()
        return self._angle_deg

    def _read_angle(self) -> None:
        """Ask the turntable for its angle (the caller holds the lock); its failure is the rig's fault."""
        table = self.devices.turntable
        if table is not None:
            try:
                self._angle_deg = round(float(np.degrees(table.angle)), 3)
            except RangekitError as exc:
                self.fault = str(exc)

    def _refuse_if_busy(self) -> None:
        if self.busy is not None:
            raise RangekitError(f"the rig is busy: {self.busy}; wait for it to finish")

    def status(self) -> dict:
        """The device status the Live page shows, at once: it never waits for the rig. The turntable is asked for
        its angle only when no other call holds the rig (a jog, a job: one serial link, one talker) and no job
        holds it; otherwise the last angle read is shown. ``controls``: the rig file's ``capture.camera``;
        ``controls_in_force``: what the camera uses, the defaults where the rig file says nothing."""
        table = self.devices.turntable
        if table is not None and self.busy is None and self._lock.acquire(blocking=False):
            try:
                self._read_angle()
            finally:
                self._lock.release()
        written = dict(self.rig.capture.get("camera", {}))
        try:
            in_force = controls_from_capture(self.rig.capture, where=str(self.rig_file)).to_dict()
        except RangekitError:
            in_force = CameraControls().to_dict()
        return {"source": self.source, "rig_file": str(self.rig_file), "busy": self.busy,
                "controls": written, "controls_in_force": {k: in_force.get(k) for k in CONTROL_FIELDS},
                "fault": self.fault, "last_reply": self.last_reply, "pattern": self.pattern,
                "camera": {"connected": self.devices.camera is not None,
                           "width": self.rig.camera.width, "height": self.rig.camera.height},
                "projector": {"connected": self.devices.projector is not None},
                "turntable": {"connected": table is not None, "turning": self.turning,
                              "angle_deg": None if table is None else self._angle_deg}}
