"""Serial turntable drivers: Horus/Ciclop (Grbl-based) and FabScan.

Both implement :class:`rangekit.rig.devices.Turntable`: angles are radians in and out; degrees and
microsteps exist only in the bytes sent to the firmware. ``rotate_to`` returns once the motion is
*finished*, not once it was accepted:

- Horus answers ``ok`` when a move is queued, so the driver polls ``?`` until the board reports
  ``Idle`` at the commanded position.
- FabScan answers ``>`` only after the move is done; moves are relative microsteps, so the driver
  keeps the step counter and sends the difference.

Faults are raised from :mod:`rangekit.errors` (see :mod:`rangekit.drivers.serial_link`); after any fault
but ``DeviceDisconnected`` the input is flushed, so the next command starts clean. ``reconnect(timeout_s)``
opens the port again and greets the board, until it is back or the time is up.

>>> tt = make_turntable("horus", "/dev/ttyUSB0")        # doctest: +SKIP
>>> tt.rotate_to(math.radians(30)); tt.angle            # doctest: +SKIP
0.5235987755982988
"""

from __future__ import annotations

import math
import re
import time
from contextlib import contextmanager
from typing import Iterator

from rangekit.drivers.retry import retry
from rangekit.drivers.serial_link import SerialLink
from rangekit.errors import (ConfigError, DeviceError, DeviceDisconnected, DeviceTimeout, InputError, ProtocolError,
                             quote)
from rangekit.rig.checks import TURNTABLE_PROTOCOLS

__all__ = ["HorusTurntable", "FabScanTurntable", "make_turntable", "TURNTABLE_PROTOCOLS"]

_HORUS_BANNER = re.compile(r"^(Horus|Grbl) \S+ \['\$' for help\]")
_BANNER_PREFIXES = ("Horus ", "Grbl ")
_STATUS = re.compile(r"^<(?P<state>[A-Za-z]+)[,|]MPos:(?P<x>[-+]?\d+(?:\.\d*)?)")
_MOVE_MARGIN = 1.5  # allow this times the expected motion time before a move times out


def _check_speed(rad_per_s: float) -> float:
    if not (math.isfinite(rad_per_s) and rad_per_s > 0):
        raise InputError(f"turntable speed must be a positive number of rad/s, got {rad_per_s!r}")
    return float(rad_per_s)


def _check_laser(n: int) -> int:
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise InputError(f"laser number must be an int >= 1, got {n!r}")
    return n


class _SerialTurntable:
    """What both drivers share: the link, the fault guard, close and the context manager."""

    def __init__(self, url: str, baud: int, *, timeout: float, steps_per_turn: int):
        if steps_per_turn <= 0:
            raise InputError(f"steps_per_turn must be positive, got {steps_per_turn!r}")
        self.steps_per_turn = int(steps_per_turn)
        self._baud, self._timeout = int(baud), float(timeout)
        self._link = SerialLink(url, baud, timeout=timeout, name="turntable")

    @property
    def url(self) -> str:
        return self._link.url

    def reconnect(self, timeout_s: float) -> None:
        """Open the port again and greet the board (``_greet``), retried until ``timeout_s`` seconds have passed:
        after the port went away or the board stopped answering. Raises the last DeviceDisconnected,
        DeviceTimeout or ProtocolError if it is not back; DeviceError if it is back but cannot go on."""
        def attempt(left_s: float) -> None:
            self._link.close()
            self._link = SerialLink(self._link.url, self._baud, timeout=min(self._timeout, left_s), name="turntable")
            self._greet()
            self._link.timeout = self._timeout

        retry(attempt, timeout_s)

    @contextmanager
    def _guard(self) -> Iterator[None]:
        """On any device fault but a disconnection, drop pending input so the next command is clean."""
        try:
            yield
        except DeviceDisconnected:
            raise
        except DeviceError:
            try:
                self._link.flush()
            except DeviceDisconnected:
                pass  # the original error is the more useful one; the next call reports the unplug
            raise

    def _steps_of(self, angle: float) -> int:
        if not math.isfinite(angle):
            raise InputError(f"turntable angle must be a finite number of radians, got {angle!r}")
        return round(angle / (2 * math.pi) * self.steps_per_turn)

    def close(self) -> None:
        """Close the serial port (the board keeps its state)."""
        self._link.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class HorusTurntable(_SerialTurntable):
    """Horus / Ciclop turntable board (Grbl-based firmware, axis X in degrees).

    Parameters
    ----------
    url : str
        Serial port or pyserial URL.
    baud : int, optional
        115200 for the Horus firmware.
    timeout : float, optional
        Seconds to wait for any single reply (``ok``, the banner, a status report).
    poll_interval : float, optional
        Seconds between ``?`` status polls while a move runs.
    steps_per_turn : int, optional
        Microsteps per table turn (3200 by default); targets are rounded to a whole microstep.
    speed : float, optional
        Initial speed in rad/s, sent as ``G1 F<deg/min>``.

    Raises
    ------
    DeviceDisconnected
        If the port cannot be opened.
    DeviceTimeout
        If nothing answers Ctrl-X.
    ProtocolError
        If something other than the Horus banner answers Ctrl-X (wrong firmware or baud rate).
    """

    def __init__(self, url: str, baud: int = 115200, *, timeout: float = 2.0, poll_interval: float = 0.05,
                 steps_per_turn: int = 3200, speed: float = math.radians(30)):
        super().__init__(url, baud, timeout=timeout, steps_per_turn=steps_per_turn)
        self.poll_interval = float(poll_interval)
        self._span: tuple[float, float] | None = None  # degrees: where the table is, between these two
        try:
            self._speed = _check_speed(speed)
            self._greet()
        except BaseException:
            self._link.close()
            raise

    def _greet(self) -> None:
        """Ctrl-X, the banner, the speed; after a reconnection the board must still hold its origin."""
        self.banner = self._handshake()
        self.set_speed(self._speed)
        if self._span is not None:
            _, x_deg, _ = self._status(time.monotonic() + self._link.timeout)
            lo, hi = sorted(self._span)
            tol_deg = 0.5 * 360.0 / self.steps_per_turn
            if not lo - tol_deg <= x_deg <= hi + tol_deg:
                was = f"{lo:.3f} deg" if hi - lo <= tol_deg else f"between {lo:.3f} and {hi:.3f} deg"
                raise DeviceError(f"{self._link.label}: back, but at X={x_deg:.3f} deg where the table was at {was}: "
                                  "the board restarted and lost its origin; turn the table back to where the scan "
                                  "started (angle 0) before continuing")

    # -- protocol --------------------------------------------------------------------------------

    def _handshake(self) -> str:
        """Soft-reset with Ctrl-X and wait for ``Horus <version> ['$' for help]``."""
        link = self._link
        link.flush(quiet=0.01, max_time=0.2)
        link.write(b"\x18", what="Ctrl-X (0x18)")
        deadline = time.monotonic() + link.timeout
        seen: list[str] = []
        while True:
            try:
                line = link.read_line(deadline, waiting_for="Horus banner").strip()
            except DeviceTimeout as exc:
                received = "".join(s + "\n" for s in seen).encode() + link.pending
                link.flush()
                if not received:
                    raise DeviceTimeout(f"{link.label}: no answer to Ctrl-X (0x18) within {link.timeout:.1f} s; "
                                        f"is the board powered and on this port?") from exc
                raise ProtocolError(f"{link.label}: expected the banner \"Horus <version> ['$' for help]\" "
                                    f"after Ctrl-X (0x18), received {quote(received)}; is this a Horus/Ciclop "
                                    f"board (protocol 'horus') at {link.baud} baud?") from exc
            except ProtocolError:
                link.flush()
                raise
            if _HORUS_BANNER.match(line):
                link.flush(quiet=0.01, max_time=0.2)
                return line
            if line:
                seen.append(line)

    def _command(self, text: str) -> list[str]:
        with self._guard():
            return self._link.command(text, "ok", reset_prefixes=_BANNER_PREFIXES)

    def _status(self, deadline: float) -> tuple[str, float, str]:
        """Send ``?`` and return (state, X in degrees, the raw report)."""
        link = self._link
        link.write(b"?", what="'?' (status query)")
        while True:
            line = link.read_line(deadline, waiting_for="status report '<...>'").strip()
            if not line or line == "ok" or line.startswith("["):
                continue  # a late 'ok' or a [MSG:...] line is not an answer to '?'
            if line.startswith(_BANNER_PREFIXES):
                raise ProtocolError(f"{link.label}: reset during a status query: expected '<Idle|Run,"
                                    f"MPos:...>', received the boot banner {quote(line)}; the origin is reset")
            m = _STATUS.match(line)
            if m is None:
                raise ProtocolError(f"{link.label}: expected a status report '<Idle,MPos:x,y,z,...>' after "
                                    f"'?', received {quote(line)}")
            return m["state"], float(m["x"]), line

    # -- Turntable protocol ----------------------------------------------------------------------

    @property
    def angle(self) -> float:
        """The angle the board reports now, in radians (0 = last ``zero()``)."""
        with self._guard():
            _, x_deg, _ = self._status(time.monotonic() + self._link.timeout)
        return math.radians(x_deg)

    def rotate_to(self, angle: float) -> None:
        """Move to ``angle`` radians (absolute, rounded to a microstep); return once the board is Idle there.

        Raises DeviceTimeout if the motion does not finish within the expected time (distance / speed,
        times 1.5, plus ``timeout``), CommandError on ``error:``, ProtocolError on a reset or garbage.
        """
        target_deg = self._steps_of(angle) * 360.0 / self.steps_per_turn
        tol_deg = 0.5 * 360.0 / self.steps_per_turn
        link = self._link
        with self._guard():
            _, start_deg, _ = self._status(time.monotonic() + link.timeout)
            expected_s = abs(target_deg - start_deg) / math.degrees(self._speed)
            command = f"G1 X{target_deg:.4f}"
            self._span = (start_deg, target_deg)
            link.command(command, "ok", reset_prefixes=_BANNER_PREFIXES)
            limit_s = link.timeout + _MOVE_MARGIN * expected_s
            deadline = time.monotonic() + limit_s
            while True:
                # 'ok' only means queued: done means Idle *at* the target (Idle before the move starts
                # is possible on real Grbl, so the position must match too).
                state, x_deg, report = self._status(time.monotonic() + link.timeout)
                if state.lower() == "idle" and abs(x_deg - target_deg) <= tol_deg:
                    self._span = (x_deg, x_deg)
                    return
                if state.lower() == "alarm":
                    raise DeviceError(f"{link.label}: alarm during {command!r}: {quote(report)}; "
                                      f"reconnect (Ctrl-X) and zero the table")
                if time.monotonic() > deadline:
                    raise DeviceTimeout(f"{link.label}: motion {command!r} not finished within {limit_s:.1f} s; "
                                        f"expected Idle at X={target_deg:.3f}, last status {quote(report)}")
                time.sleep(self.poll_interval)

    # -- extras ----------------------------------------------------------------------------------

    def zero(self) -> None:
        """Make the current position angle 0 (``G50``)."""
        self._command("G50")

    def set_speed(self, rad_per_s: float) -> None:
        """Set the rotation speed in rad/s (``G1 F<deg/min>``)."""
        rad_per_s = _check_speed(rad_per_s)
        self._command(f"G1 F{math.degrees(rad_per_s) * 60.0:.3f}")
        self._speed = rad_per_s

    def set_acceleration(self, rad_per_s2: float) -> None:
        """Set the acceleration in rad/s^2 (``$120=<deg/s^2>``)."""
        if not (math.isfinite(rad_per_s2) and rad_per_s2 > 0):
            raise InputError(f"turntable acceleration must be a positive number of rad/s^2, got {rad_per_s2!r}")
        self._command(f"$120={math.degrees(rad_per_s2):.3f}")

    def enable(self, on: bool = True) -> None:
        """Power the motor (``M17``) or release it (``M18``)."""
        self._command("M17" if on else "M18")

    def laser(self, n: int, on: bool) -> None:
        """Switch laser ``n`` (1, 2, ...) on (``M71T<n>``) or off (``M70T<n>``)."""
        self._command(f"M{71 if on else 70}T{_check_laser(n)}")


class FabScanTurntable(_SerialTurntable):
    """FabScan turntable board: echoes each byte, answers ``>`` once a line is done, relative moves.

    Parameters
    ----------
    url, baud : as for :class:`HorusTurntable`; 57600 baud by default.
    timeout : float, optional
        Seconds to wait for a reply to a command that does not move.
    reset_delay : float, optional
        Seconds to wait after opening the port: opening resets the Arduino, which then ignores input
        for about 2 s.
    steps_per_turn : int, optional
        Microsteps per turn (3200).
    speed : float, optional
        Rotation speed in rad/s, sent as ``F<deg/min>`` with every move.

    The board cannot report its position: :attr:`angle` is the driver's step counter. After a failed
    move the position is unknown until :meth:`zero` is called.
    """

    def __init__(self, url: str, baud: int = 57600, *, timeout: float = 2.0, reset_delay: float = 2.0,
                 steps_per_turn: int = 3200, speed: float = math.radians(30)):
        super().__init__(url, baud, timeout=timeout, steps_per_turn=steps_per_turn)
        self._speed = _check_speed(speed)
        self._steps: int | None = 0
        self._reset_delay = float(reset_delay)
        try:
            self._greet()
        except BaseException:
            self._link.close()
            raise

    def _greet(self) -> None:
        """Wait out the reset that opening the port causes, then ask the version (``M200``). The step counter
        is kept: the board does not know its position (after a failed move it is unknown anyway)."""
        time.sleep(self._reset_delay)
        self._link.flush(quiet=0.01, max_time=0.2)
        info = self._command("M200")
        self.version = info[0] if info else ""

    def _command(self, text: str, *, timeout: float | None = None) -> list[str]:
        """Send a line; check its echo; return the lines between the echo and the ``>`` prompt."""
        link = self._link
        with self._guard():
            link.write_line(text)
            deadline = time.monotonic() + (link.timeout if timeout is None else timeout)
            echo = link.read_until((b"\n", b"\r"), deadline, waiting_for=f"echo of {text!r}")
            if echo.strip(b"\r\n") != text.encode("ascii"):
                raise ProtocolError(f"{link.label}: expected the echo {text!r} then '>', received {quote(echo)}; "
                                    f"is this a FabScan board (protocol 'fabscan') at {link.baud} baud?")
            rest = link.read_until((b">",), deadline, waiting_for="prompt '>'")
        lines = rest[:-1].decode("ascii").replace("\r", "\n").split("\n")
        return [s.strip() for s in lines if s.strip()]

    @property
    def angle(self) -> float:
        """The angle in radians since the last :meth:`zero`, from the step counter."""
        if self._steps is None:
            raise DeviceError(f"{self._link.label}: position unknown after a failed move; "
                              f"turn the table to a known angle and call zero()")
        return self._steps * 2 * math.pi / self.steps_per_turn

    def rotate_to(self, angle: float) -> None:
        """Move to ``angle`` radians (absolute, rounded to a microstep); returns when the board says done."""
        target = self._steps_of(angle)
        if self._steps is None:
            raise DeviceError(f"{self._link.label}: position unknown after a failed move, so no relative "
                              f"move to {angle:.4f} rad can be computed; turn the table to a known angle "
                              f"and call zero()")
        delta = target - self._steps
        if delta == 0:
            return
        feed_deg_per_min = math.degrees(self._speed) * 60.0
        expected_s = abs(delta) * 360.0 / self.steps_per_turn / feed_deg_per_min * 60.0
        self._steps = None  # unknown until the board confirms
        self._command(f"G01 T{delta} F{feed_deg_per_min:.0f}",
                      timeout=self._link.timeout + _MOVE_MARGIN * expected_s)
        self._steps = target

    def zero(self) -> None:
        """Make the current position angle 0 (resets the driver's step counter)."""
        self._steps = 0

    def set_speed(self, rad_per_s: float) -> None:
        """Set the speed in rad/s for the next moves (sent with each move as ``F<deg/min>``)."""
        self._speed = _check_speed(rad_per_s)

    def enable(self, on: bool = True) -> None:
        """Power the motor (``M17``) or release it (``M18``)."""
        self._command("M17" if on else "M18")

    def laser(self, n: int, on: bool) -> None:
        """Switch laser 1 (``M19``/``M20``) or laser 2 (``M21``/``M22``) on or off."""
        if _check_laser(n) > 2:
            raise InputError(f"FabScan boards drive lasers 1 and 2, got laser {n}")
        self._command(f"M{19 + 2 * (n - 1) + (0 if on else 1)}")


_DRIVERS = {"horus": HorusTurntable, "fabscan": FabScanTurntable}  # one per rangekit.rig.checks.TURNTABLE_PROTOCOLS


def make_turntable(protocol: str, url: str, baud: int | None = None, **kw) -> HorusTurntable | FabScanTurntable:
    """Open the turntable named in a rig file: ``protocol`` is ``"horus"`` or ``"fabscan"``.

    ``baud=None`` uses the protocol's default; other keywords go to the driver's constructor.

    Raises
    ------
    ConfigError
        If ``protocol`` is not known; the message lists the known ones.
    """
    key = str(protocol).strip().lower()
    if key not in TURNTABLE_PROTOCOLS:
        raise ConfigError(f"turntable protocol {protocol!r} is not known; known protocols: "
                          f"{', '.join(repr(k) for k in sorted(TURNTABLE_PROTOCOLS))}")
    cls = _DRIVERS[key]
    return cls(url, **kw) if baud is None else cls(url, baud, **kw)
