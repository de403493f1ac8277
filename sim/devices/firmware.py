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
``"unplug"`` and ``"stall"`` act at once. ``"unplug"``: the pty is unplugged (:class:`rangekit.sim.devices.
pty_port.PtyPort`: EIO on the driver's side, the path and ``link`` gone) until :meth:`SimFirmware.replug`.
``"stall"``: the board stops answering (it reads and drops every byte, the table stops where it is) until
:meth:`SimFirmware.recover`. ``link``: a path kept as a symbolic link to the board's current pty.
"""

from __future__ import annotations

import collections
import os
import re
import select
import threading
import time
from typing import Iterable

import numpy as np

from rangekit.sim.devices.fabscan_firmware import WORD as _WORD, FabScanProtocol
from rangekit.sim.devices.pty_port import PtyPort

__all__ = ["SimFirmware", "start_firmware", "FAULTS", "HORUS_BANNER"]

FAULTS = ("garbage", "silence", "partial", "reboot", "error", "unplug", "stall")
HORUS_BANNER = b"\r\nHorus 0.2 ['$' for help]\r\n"


class SimFirmware(FabScanProtocol):
    """One simulated board on a pty. Use :func:`start_firmware`; stop it with :meth:`stop`. The FabScan protocol
    is :class:`rangekit.sim.devices.fabscan_firmware.FabScanProtocol`.

    Attributes
    ----------
    port : str
        Slave pty path to open with a driver (``/dev/pts/N``).
    kind : str
        ``"horus"`` or ``"fabscan"``.
    link : str or None
        The symbolic link kept to ``port`` while the board is plugged in (None: no link).
    status_queries : int
        How many ``?`` status reports the Horus board has sent (to check that drivers poll).
    lasers : dict[int, bool]; motors_on : bool; acceleration : float | None
        Last state set by commands.
    ignored : bytearray
        Every byte received (and dropped) while the board was stalled.
    """

    def __init__(self, kind: str, *, time_scale: float = 0.01, faults: Iterable[str] | None = None,
                 steps_per_turn: int = 3200, feed_deg_per_min: float = 1800.0, boot_time: float = 0.0,
                 seed: int = 0, link: str | os.PathLike | None = None):
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
        self.ignored = bytearray()
        self._rng = np.random.default_rng(seed)
        self._lock = threading.RLock()
        self._faults: collections.deque[str] = collections.deque()
        self._stop = threading.Event()
        self._unplug = threading.Event()
        self._stalled = threading.Event()
        # motion state (degrees): position at _seg_t0, then the queued moves (target, duration in s)
        self._pos = 0.0
        self._seg_t0 = time.monotonic()
        self._moves: collections.deque[tuple[float, float]] = collections.deque()
        self._line = bytearray()
        self._line_fault: str | None = None
        self._line_started = False
        self._booting_until = time.monotonic() + self.boot_time

        self._pty = PtyPort(link)
        self.link = self._pty.link
        self._serve()
        for f in faults or ():
            self.inject(f)

    @property
    def port(self) -> str:
        return self._pty.port

    def _serve(self) -> None:
        self._unplug.clear()
        self._thread = threading.Thread(target=self._run, name=f"sim-{self.kind}-firmware", daemon=True)
        self._thread.start()

    # -- public --------------------------------------------------------------------------------

    def inject(self, fault: str) -> None:
        """Queue a fault for the next command (``"unplug"`` and ``"stall"`` happen at once). See the module doc."""
        if fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}; known: {', '.join(FAULTS)}")
        if fault == "unplug":
            self._pty.remove_link()
            self._unplug.set()
            if threading.current_thread() is not self._thread:
                self._thread.join(timeout=1.0)
            return
        if fault == "stall":
            with self._lock:      # the table stops where it is
                pos = self.position_deg
                self._moves.clear()
                self._pos, self._seg_t0 = pos, time.monotonic()
            self._stalled.set()
            return
        with self._lock:
            self._faults.append(fault)

    def replug(self, *, restarted: bool = False) -> None:
        """Plug an unplugged board in again: a new pty (``port`` changes, ``link`` follows). The board's state
        (position, lasers) is kept, or with ``restarted`` lost as a board powered from USB loses it (position
        0 wherever the table stands, lasers off). Raises RuntimeError if the board is not unplugged."""
        if not self._unplug.is_set() or self._stop.is_set():
            raise RuntimeError(f"sim {self.kind} firmware: replug() needs an unplugged board")
        self._thread.join(timeout=2.0)
        if restarted:
            self._reset()
            self.lasers = {n: False for n in self.lasers}
        self._pty.plug_in()
        self._serve()

    def recover(self) -> None:
        """End a ``"stall"``: the board answers again (what it received meanwhile is lost)."""
        self._stalled.clear()

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
        self._pty.close()

    def __enter__(self) -> "SimFirmware":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- I/O loop ------------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            if self._unplug.is_set():
                self._pty.unplug()
                return
            try:
                master = self._pty.master
                ready, _, _ = select.select([master], [], [], 0.005)
                data = os.read(master, 4096) if ready else b""
            except OSError:
                return
            if self._stalled.is_set():
                self.ignored += data    # a hung board: what it is sent is lost
                continue
            for b in data:
                if self._unplug.is_set() or self._stop.is_set() or self._stalled.is_set():
                    break
                if time.monotonic() < self._booting_until:
                    continue  # the bootloader ignores input
                self._on_byte(b)

    def _send(self, data: bytes) -> None:
        if data and self._pty.master >= 0 and not self._stalled.is_set():
            try:
                os.write(self._pty.master, data)
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


def start_firmware(kind: str, *, time_scale: float = 0.01, faults: Iterable[str] | None = None,
                   **kw) -> SimFirmware:
    """Start a simulated ``"horus"`` or ``"fabscan"`` board on a new pty; see :class:`SimFirmware`.

    ``time_scale`` multiplies every motion time (0.01: a 3 s move takes 30 ms). Other keywords:
    ``steps_per_turn=3200``, ``feed_deg_per_min=1800``, ``boot_time=0`` (seconds FabScan/Horus ignore
    input after start and after a reboot), ``seed=0`` (garbage bytes).
    """
    return SimFirmware(kind, time_scale=time_scale, faults=faults, **kw)
