"""Simulated turntable firmware on a pseudo-terminal: the real drivers talk to it with bytes only.

``start_firmware("horus")`` opens a pty, runs a Horus (Grbl-based) or FabScan board in a background
thread on the master side, and gives the slave path to hand to a driver:

>>> fw = start_firmware("horus", time_scale=0.01)       # doctest: +SKIP
>>> tt = HorusTurntable(fw.port); tt.rotate_to(0.5)     # doctest: +SKIP
>>> fw.position_deg, fw.stop()                          # doctest: +SKIP

Byte protocols (the subset the drivers use):

- Horus, 115200 baud: ``\\x18`` (Ctrl-X) answers ``\\r\\nHorus 0.2 ['$' for help]\\r\\n``; ``?`` (realtime,
  no line end) answers ``<Idle|Run,MPos:x,0.000,0.000,WPos:...>``; each ``\\r``- or ``\\n``-ended line
  answers ``ok`` or ``error: ...``. ``G1 X<deg>`` queues an absolute move (rounded to a microstep),
  ``G1 F<deg/min>`` sets the feed, ``G50`` zeroes, ``M17``/``M18``, ``M71T<n>``/``M70T<n>``, ``$120=<a>``.
- FabScan, 57600 baud: every byte is echoed; each line end (``\\r`` or ``\\n``) answers ``>`` once the
  command is done. ``G01``/``G02 T<steps> F<deg/min>`` block for the move (relative), ``M200`` prints the
  version, ``M17``-``M22`` are accepted. Input is ignored for ``boot_time`` after start and after a reboot.

Motion time: ``|delta| / feed`` minutes, times ``time_scale``.

Faults (``inject`` or ``faults=``), each applied to the next command line (or Ctrl-X):
``"garbage"`` (the reply becomes random non-ASCII bytes), ``"silence"`` (the line is swallowed),
``"partial"`` (only the reply's first byte is sent), ``"reboot"`` (the board resets mid-command: banner
for Horus, silence for FabScan, position back to 0), ``"error"`` (Horus: ``error:`` instead of ``ok``).
``"unplug"`` acts at once: the master side is closed.
"""

from __future__ import annotations

import collections
import os
import re
import select
import threading
import time
import tty
from typing import Iterable

import numpy as np

__all__ = ["SimFirmware", "start_firmware", "FAULTS", "HORUS_BANNER"]

FAULTS = ("garbage", "silence", "partial", "reboot", "error", "unplug")
HORUS_BANNER = b"\r\nHorus 0.2 ['$' for help]\r\n"
FABSCAN_VERSION = "FabScan v0.1 (rangekit sim)"
_WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


class SimFirmware:
    """One simulated board on a pty. Use :func:`start_firmware`; stop it with :meth:`stop`.

    Attributes
    ----------
    port : str
        Slave pty path to open with a driver (``/dev/pts/N``).
    kind : str
        ``"horus"`` or ``"fabscan"``.
    status_queries : int
        How many ``?`` status reports the Horus board has sent (to check that drivers poll).
    lasers : dict[int, bool]; motors_on : bool; acceleration : float | None
        Last state set by commands.
    """

    def __init__(self, kind: str, *, time_scale: float = 0.01, faults: Iterable[str] | None = None,
                 steps_per_turn: int = 3200, feed_deg_per_min: float = 1800.0, boot_time: float = 0.0,
                 seed: int = 0):
        if kind not in ("horus", "fabscan"):
            raise ValueError(f"firmware kind must be 'horus' or 'fabscan', got {kind!r}")
        self.kind = kind
        self.time_scale = float(time_scale)
        self.steps_per_turn = int(steps_per_turn)
        self.feed = float(feed_deg_per_min)
        self.boot_time = float(boot_time)
        self.status_queries = 0
        self.lasers: dict[int, bool] = {}
        self.motors_on = False
        self.acceleration: float | None = None
        self.lines: list[str] = []  # every command line received, for tests
        self._rng = np.random.default_rng(seed)
        self._lock = threading.RLock()
        self._faults: collections.deque[str] = collections.deque()
        self._stop = threading.Event()
        self._unplug = threading.Event()
        # motion state (degrees): position at _seg_t0, then the queued moves (target, duration in s)
        self._pos = 0.0
        self._seg_t0 = time.monotonic()
        self._moves: collections.deque[tuple[float, float]] = collections.deque()
        self._line = bytearray()
        self._line_fault: str | None = None
        self._line_started = False
        self._booting_until = time.monotonic() + self.boot_time

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        for f in faults or ():
            self.inject(f)
        self._thread = threading.Thread(target=self._run, name=f"sim-{kind}-firmware", daemon=True)
        self._thread.start()

    # -- public --------------------------------------------------------------------------------

    def inject(self, fault: str) -> None:
        """Queue a fault for the next command (``"unplug"`` happens at once). See the module doc."""
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {', '.join(FAULTS)}")
        if fault == "unplug":
            self._unplug.set()
            if threading.current_thread() is not self._thread:
                self._thread.join(timeout=1.0)
            return
        with self._lock:
            self._faults.append(fault)

    @property
    def position_deg(self) -> float:
        """Where the table is now, in degrees (not wrapped; 0 = last zero or boot)."""
        with self._lock:
            self._advance()
            if not self._moves:
                return self._pos
            target, duration = self._moves[0]
            frac = min(1.0, (time.monotonic() - self._seg_t0) / duration) if duration > 0 else 1.0
            return self._pos + frac * (target - self._pos)

    @property
    def moving(self) -> bool:
        with self._lock:
            self._advance()
            return bool(self._moves)

    def stop(self) -> None:
        """Stop the thread and close both pty ends (idempotent)."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=2.0)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        self._master = self._slave = -1

    def __enter__(self) -> "SimFirmware":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- I/O loop ------------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._unplug.is_set():
                os.close(self._master)
                self._master = -1
                return
            try:
                ready, _, _ = select.select([self._master], [], [], 0.005)
                data = os.read(self._master, 4096) if ready else b""
            except OSError:
                return
            for b in data:
                if self._unplug.is_set() or self._stop.is_set():
                    break
                if time.monotonic() < self._booting_until:
                    continue  # the bootloader ignores input
                self._on_byte(b)

    def _send(self, data: bytes) -> None:
        if data and self._master >= 0:
            try:
                os.write(self._master, data)
            except OSError:
                pass

    def _garbage(self, n: int = 8) -> bytes:
        return bytes(self._rng.integers(0x80, 0x100, n, dtype=np.uint8))

    def _pop_fault(self) -> str | None:
        with self._lock:
            return self._faults.popleft() if self._faults else None

    def _sleep(self, seconds: float) -> None:
        self._stop.wait(max(0.0, seconds))

    def _on_byte(self, b: int) -> None:
        if self.kind == "horus":
            self._horus_byte(b)
        else:
            self._fabscan_byte(b)

    # -- motion model --------------------------------------------------------------------------

    def _advance(self) -> None:
        """Retire finished moves (caller holds the lock)."""
        now = time.monotonic()
        while self._moves:
            target, duration = self._moves[0]
            if now - self._seg_t0 < duration:
                return
            self._moves.popleft()
            self._pos = target
            self._seg_t0 += duration

    def _duration(self, delta_deg: float, feed: float) -> float:
        return abs(delta_deg) / feed * 60.0 * self.time_scale

    def _wait_idle(self) -> None:
        while self.moving and not (self._stop.is_set() or self._unplug.is_set()):
            self._sleep(0.002)

    def _reset(self) -> None:
        with self._lock:
            self._moves.clear()
            self._pos = 0.0
            self._seg_t0 = time.monotonic()
        self._line.clear()

    # -- Horus (Grbl) ----------------------------------------------------------------------------

    def _horus_byte(self, b: int) -> None:
        if b == 0x18:  # soft reset: stop motion where it is, keep the position, send the banner
            with self._lock:
                pos = self.position_deg
                self._moves.clear()
                self._pos, self._seg_t0 = pos, time.monotonic()
            self._line.clear()
            fault = self._pop_fault()
            self._send(self._garbage() if fault == "garbage" else b"" if fault == "silence"
                       else HORUS_BANNER[:1] if fault == "partial" else HORUS_BANNER)
            return
        if b == ord("?"):  # realtime status report
            with self._lock:
                state = "Run" if self.moving else "Idle"
                x = self.position_deg
                self.status_queries += 1
            self._send(f"<{state},MPos:{x:.3f},0.000,0.000,WPos:{x:.3f},0.000,0.000>\r\n".encode())
            return
        if b in (0x0A, 0x0D):
            line = self._line.decode("ascii", "replace").strip().upper()
            self._line.clear()
            self._horus_line(line)
            return
        self._line.append(b)

    def _horus_line(self, line: str) -> None:
        self.lines.append(line)
        fault = self._pop_fault()
        if fault == "silence":
            return
        if fault == "reboot":
            self._sleep(0.002)
            self._reset()
            self._send(HORUS_BANNER)
            return
        if fault == "error":
            self._send(b"error: Bad number format\r\n")
            return
        reply = self._horus_execute(line)
        if fault == "garbage":
            reply = self._garbage()
        elif fault == "partial":
            reply = reply[:1]
        self._send(reply)

    def _horus_execute(self, line: str) -> bytes:
        ok, bad = b"ok\r\n", b"error: Unsupported command\r\n"
        words = dict(_WORD.findall(line.replace(" ", "")))
        if not line:
            return ok
        if line.startswith("$120="):
            try:
                self.acceleration = float(line[5:])
            except ValueError:
                return b"error: Bad number format\r\n"
            return ok
        code = re.match(r"^([GM])(\d+)", line)
        if code is None:
            return bad
        letter, num = code[1], int(code[2])
        if letter == "G" and num in (0, 1):
            if "F" in words:
                if float(words["F"]) <= 0:
                    return b"error: Invalid feed rate\r\n"
                self.feed = float(words["F"])
            if "X" in words:
                step = 360.0 / self.steps_per_turn
                target = round(float(words["X"]) / step) * step
                with self._lock:
                    self._advance()
                    last = self._moves[-1][0] if self._moves else self._pos
                    if not self._moves:
                        self._seg_t0 = time.monotonic()
                    self._moves.append((target, self._duration(target - last, self.feed)))
            return ok
        if letter == "G" and num == 50:
            self._wait_idle()
            with self._lock:
                self._pos, self._seg_t0 = 0.0, time.monotonic()
            return ok
        if letter == "M" and num in (17, 18):
            self.motors_on = num == 17
            return ok
        if letter == "M" and num in (70, 71) and "T" in words:
            self.lasers[int(float(words["T"]))] = num == 71
            return ok
        return bad

    # -- FabScan ---------------------------------------------------------------------------------

    def _fabscan_byte(self, b: int) -> None:
        if not self._line_started:
            self._line_started = True
            self._line_fault = self._pop_fault()
        fault = self._line_fault
        is_end = b in (0x0A, 0x0D)
        if fault == "reboot" and self._line:
            # the board resets after echoing one byte: position back to 0, and the rest of the line
            # (sent in the same burst) is lost while it boots
            self._reset()
            self._line_started, self._line_fault = False, None
            self._booting_until = time.monotonic() + max(self.boot_time, 0.02)
            return
        if fault in (None, "error"):
            self._send(bytes([b]))
        elif fault == "garbage":
            self._send(self._garbage(1))
        elif fault in ("partial", "reboot") and not self._line and not is_end:
            self._send(bytes([b]))
        if not is_end:
            self._line.append(b)
            return
        line = self._line.decode("ascii", "replace").strip().upper()
        self._line.clear()
        self._line_started, self._line_fault = False, None
        if fault == "silence":
            return
        self.lines.append(line)
        reply = self._fabscan_execute(line) + b">"
        if fault == "garbage":
            reply = self._garbage()
        elif fault == "partial":
            reply = b""
        self._send(reply)

    def _fabscan_execute(self, line: str) -> bytes:
        words = dict(_WORD.findall(line.replace(" ", "")))
        code = re.match(r"^([GM])(\d+)", line)
        if code is None:
            return b""
        letter, num = code[1], int(code[2])
        if letter == "G" and num in (1, 2) and "T" in words:
            if "F" in words and float(words["F"]) > 0:
                self.feed = float(words["F"])
            delta = int(float(words["T"])) * 360.0 / self.steps_per_turn
            duration = self._duration(delta, self.feed)
            with self._lock:
                self._advance()
                self._seg_t0 = time.monotonic()
                self._moves.append((self._pos + delta, duration))
            self._wait_idle()  # FabScan blocks until the move is done
        elif letter == "M" and num == 200:
            return FABSCAN_VERSION.encode() + b"\r\n"
        elif letter == "M" and num in (17, 18):
            self.motors_on = num == 17
        elif letter == "M" and 19 <= num <= 22:
            self.lasers[1 + (num - 19) // 2] = (num - 19) % 2 == 0
        return b""


def start_firmware(kind: str, *, time_scale: float = 0.01, faults: Iterable[str] | None = None,
                   **kw) -> SimFirmware:
    """Start a simulated ``"horus"`` or ``"fabscan"`` board on a new pty; see :class:`SimFirmware`.

    ``time_scale`` multiplies every motion time (0.01: a 3 s move takes 30 ms). Other keywords:
    ``steps_per_turn=3200``, ``feed_deg_per_min=1800``, ``boot_time=0`` (seconds FabScan/Horus ignore
    input after start and after a reboot), ``seed=0`` (garbage bytes).
    """
    return SimFirmware(kind, time_scale=time_scale, faults=faults, **kw)
