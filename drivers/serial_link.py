"""A line-oriented serial link with a deadline on every read and rangekit errors.

Works over anything :func:`serial.serial_for_url` opens: real ports (``/dev/ttyUSB0``, ``COM3``),
pty paths (the simulated firmware of :mod:`rangekit.sim.devices.firmware`) and ``socket://host:port``.

Every failure is raised from :mod:`rangekit.errors` with the device, the port, the last command, what
was expected and the bytes that did arrive:

- the port cannot be opened, or goes away (``serial.SerialException``, ``OSError``) -> ``DeviceDisconnected``
- nothing complete arrives before the deadline -> ``DeviceTimeout`` (partial bytes in the message)
- bytes that are not printable ASCII (wrong baud rate, wrong firmware), or a reply longer than
  :data:`MAX_REPLY_BYTES` without its terminator -> ``ProtocolError``
- an ``error...`` reply to :meth:`SerialLink.command` -> ``CommandError``

After any of these but ``DeviceDisconnected``, call :meth:`SerialLink.flush` before the next command.
Messages quote at most :data:`rangekit.errors.QUOTE_LIMIT` bytes of what the device sent, escaped
(:func:`rangekit.errors.quote`), so a babbling device cannot flood the terminal or the memory.
"""

from __future__ import annotations

import time

import serial

from rangekit.errors import CommandError, DeviceDisconnected, DeviceTimeout, ProtocolError, one_line, quote

__all__ = ["SerialLink", "MAX_REPLY_BYTES"]

_READ_SLICE = 0.02  # seconds; longest a single read blocks, so deadlines overshoot by at most this
_ALLOWED = bytes(range(0x20, 0x7F)) + b"\t\n\r"  # printable ASCII, tab, CR, LF
#: The longest reply (bytes up to and including its terminator) a read accepts: longer is a ProtocolError.
MAX_REPLY_BYTES = 4096
_GARBAGE_SETTLE = 0.05  # seconds to keep reading after a bad byte, so the message shows the whole burst
_CHECK = "was the device unplugged? check its USB cable and power"


class SerialLink:
    """A serial connection that speaks lines of ASCII.

    Parameters
    ----------
    url : str
        A pyserial URL or port path: ``/dev/ttyUSB0``, ``/dev/pts/3``, ``socket://127.0.0.1:7777``.
    baud : int
        Baud rate (ignored by ptys and sockets, but named in errors about garbage).
    timeout : float, optional
        Default seconds to wait for a reply in :meth:`command`.
    name : str, optional
        What the device is ("turntable"); errors start with ``"{name} at {url}: "``.

    Raises
    ------
    DeviceDisconnected
        If the port cannot be opened; the message names the port and how to list ports.
    """

    def __init__(self, url: str, baud: int, *, timeout: float = 2.0, name: str = "device"):
        self.url = str(url)
        self.baud = int(baud)
        self.timeout = float(timeout)
        self.name = name
        self._buf = bytearray()
        self._last_sent: str = "opening the port"
        self._last_write_t = time.monotonic()
        try:
            self._port = serial.serial_for_url(self.url, baudrate=self.baud, timeout=_READ_SLICE,
                                               write_timeout=self.timeout)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceDisconnected(
                f"{self.label}: cannot open the port ({exc}); check the cable and the port name, "
                f"list serial ports with `rangekit devices` (or `python -m serial.tools.list_ports`)"
            ) from exc

    @property
    def label(self) -> str:
        """``"turntable at /dev/ttyUSB0"``: how errors name this device."""
        return f"{self.name} at {self.url}"

    @property
    def pending(self) -> bytes:
        """Bytes received but not yet returned by a read (e.g. a partial reply after a timeout)."""
        return bytes(self._buf)

    # -- writing -------------------------------------------------------------------------------

    def write(self, data: bytes, *, what: str | None = None) -> None:
        """Send raw bytes; ``what`` is how later errors name them (default: the bytes' repr)."""
        try:
            self._port.write(data)
            self._port.flush()
        except (serial.SerialException, OSError) as exc:
            raise DeviceDisconnected(f"{self.label}: writing {quote(data)} failed ({one_line(exc)}); "
                                     f"{_CHECK}") from exc
        self._last_sent = what if what is not None else repr(data)
        self._last_write_t = time.monotonic()

    def write_line(self, text: str, eol: bytes = b"\n") -> None:
        """Send ``text`` (ASCII) followed by ``eol``."""
        self.write(text.encode("ascii") + eol, what=text)

    @property
    def _sent(self) -> str:
        return self._last_sent if self._last_sent == "opening the port" else repr(self._last_sent)

    # -- reading -------------------------------------------------------------------------------

    def read_until(self, terminators: tuple[bytes, ...], deadline: float, *,
                   waiting_for: str = "reply") -> bytes:
        """Read until one of ``terminators`` arrives; return the bytes up to and including it.

        ``deadline`` is a :func:`time.monotonic` time. Bytes after the terminator stay buffered for
        the next read; on a timeout the partial bytes stay buffered too (and are in the message).

        Raises DeviceTimeout, ProtocolError (non-ASCII bytes), DeviceDisconnected.
        """
        while True:
            ends = [self._buf.find(t) + len(t) for t in terminators if t in self._buf]
            end = min(ends) if ends else len(self._buf)
            if self._buf[:end].translate(None, _ALLOWED):
                self._read_chunk(min(deadline, time.monotonic() + _GARBAGE_SETTLE), drain=True)
                bad = bytes(self._buf)
                self._buf.clear()
                raise ProtocolError(
                    f"{self.label}: expected {waiting_for} after {self._sent}, received "
                    f"non-ASCII bytes {quote(bad)}; check the baud rate ({self.baud}) and that the board "
                    f"runs the expected firmware")
            if end > MAX_REPLY_BYTES:
                bad = bytes(self._buf)
                self._buf.clear()
                raise ProtocolError(
                    f"{self.label}: expected {waiting_for} after {self._sent}, received a reply of more "
                    f"than {MAX_REPLY_BYTES} bytes without its end ({quote(bad)}); check the baud rate "
                    f"({self.baud}) and that the board runs the expected firmware")
            if ends:
                out = bytes(self._buf[:end])
                del self._buf[:end]
                return out
            if time.monotonic() >= deadline:
                waited = max(0.0, deadline - self._last_write_t)
                raise DeviceTimeout(f"{self.label}: no {waiting_for} within {waited:.1f} s after "
                                    f"{self._sent}; received {quote(self._buf)}; check that the board is powered "
                                    "and its USB cable")
            self._read_chunk(deadline)

    def read_line(self, deadline: float | None = None, *, waiting_for: str = "line") -> str:
        """Read one line (ended by ``\\n``; ``\\r`` is stripped) before ``deadline`` (monotonic time).

        ``deadline=None`` means ``timeout`` seconds from now. Raises like :meth:`read_until`.
        """
        if deadline is None:
            deadline = time.monotonic() + self.timeout
        raw = self.read_until((b"\n",), deadline, waiting_for=waiting_for)
        return raw.decode("ascii").strip("\r\n")

    def _read_chunk(self, deadline: float, *, drain: bool = False) -> None:
        """Append what arrives within one read slice (or, with ``drain``, until ``deadline``)."""
        while True:
            try:
                chunk = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                raise DeviceDisconnected(f"{self.label}: reading failed while waiting after "
                                         f"{self._sent} ({one_line(exc)}); {_CHECK}") from exc
            self._buf += chunk
            if not drain or time.monotonic() >= deadline or len(self._buf) > MAX_REPLY_BYTES:
                return

    # -- commands ------------------------------------------------------------------------------

    def command(self, text: str, expect: str = "ok", *, timeout: float | None = None,
                error_prefix: str = "error", reset_prefixes: tuple[str, ...] = (),
                eol: bytes = b"\n") -> list[str]:
        """Send one line and read lines until one equals ``expect``; return the lines before it.

        Empty lines are skipped. A line starting with ``error_prefix`` raises CommandError; one starting
        with any of ``reset_prefixes`` (a boot banner) raises ProtocolError saying the device reset
        during ``text``.
        """
        self.write_line(text, eol)
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        lines: list[str] = []
        while True:
            line = self.read_line(deadline, waiting_for=repr(expect)).strip()
            if not line:
                continue
            if line == expect:
                return lines
            if error_prefix and line.lower().startswith(error_prefix):
                raise CommandError(f"{self.label}: {text!r} was refused: expected {expect!r}, "
                                   f"received {quote(line)}")
            if any(line.startswith(p) for p in reset_prefixes):
                raise ProtocolError(f"{self.label}: reset during {text!r}: expected {expect!r}, received "
                                    f"the boot banner {quote(line)}; the command was lost and the position "
                                    f"origin is reset")
            lines.append(line)

    def flush(self, *, quiet: float = 0.05, max_time: float = 1.0) -> bytes:
        """Discard pending input: reset the input buffer, then drain until ``quiet`` s pass silently.

        Call this after an error so the next command does not read a stale reply. Returns what was
        discarded (for logs). Raises DeviceDisconnected if the port is gone.
        """
        dropped = bytes(self._buf)
        self._buf.clear()
        t_end = time.monotonic() + max_time
        try:
            self._port.reset_input_buffer()
            last = time.monotonic()
            while time.monotonic() < t_end and time.monotonic() - last < quiet:
                chunk = self._port.read(max(1, self._port.in_waiting))
                if chunk:
                    dropped += chunk
                    last = time.monotonic()
        except (serial.SerialException, OSError) as exc:
            raise DeviceDisconnected(f"{self.label}: flushing input failed ({one_line(exc)}); "
                                     f"{_CHECK}") from exc
        return dropped

    def close(self) -> None:
        """Close the port (idempotent; errors while closing are ignored, the port is gone anyway)."""
        try:
            self._port.close()
        except (serial.SerialException, OSError):
            pass

    def __enter__(self) -> "SerialLink":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
