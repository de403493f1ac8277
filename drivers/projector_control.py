"""Projector control (power, blanking, input source) over serial (Epson ESC/VP21) or the network
(PJLink class 1, TCP 4352). The patterns themselves go over HDMI (:mod:`rangekit.drivers.display`).

ESC/VP21: 9600 baud, commands end with ``\\r``; the projector answers ``:`` when ready, a query's value
line before it (``PWR=01``), or ``ERR``. PJLink: on connect the projector greets ``PJLINK 0`` (no
authentication) or ``PJLINK 1 <seed>`` (prefix every command with md5(seed + password)); commands
``%1POWR 1``, ``%1AVMT 31``, ``%1INPT 31`` are answered ``%1POWR=OK`` or ``=ERR1..4`` / ``PJLINK ERRA``.
"""

from __future__ import annotations

import hashlib
import socket
import time

from rangekit.drivers.serial_link import MAX_REPLY_BYTES, SerialLink
from rangekit.errors import CommandError, ConfigError, DeviceDisconnected, DeviceTimeout, ProtocolError, quote
from rangekit.rig.checks import PROJECTOR_PROTOCOLS

__all__ = ["EscVp21Projector", "PJLinkProjector", "make_projector_control", "PROJECTOR_PROTOCOLS"]


class EscVp21Projector:
    """Epson-style serial control: ``power``, ``is_on``, ``blank``, ``source``."""

    def __init__(self, url: str, baud: int = 9600, *, timeout: float = 2.0, name: str = "projector") -> None:
        self.link = SerialLink(url, baud, timeout=timeout, name=name)
        try:
            self._command("")  # an empty line must give the ':' prompt
        except Exception:
            self.link.close()
            raise

    def _command(self, text: str) -> list[str]:
        """Send ``text``; return the lines before the ``:`` prompt; ``ERR`` raises CommandError."""
        self.link.write(text.encode("ascii") + b"\r", what=text or "<CR>")
        deadline = time.monotonic() + self.link.timeout
        raw = self.link.read_until((b":",), deadline, waiting_for="':' prompt").decode("ascii")
        lines = [ln.strip() for ln in raw[:-1].replace("\r", "\n").split("\n") if ln.strip()]
        if any(ln == "ERR" for ln in lines):
            self.link.flush()
            raise CommandError(f"{self.link.label}: {text!r} was refused (ERR); the projector may be off, "
                               "warming up or without that input")
        return lines

    def power(self, on: bool) -> None:
        self._command("PWR ON" if on else "PWR OFF")

    def is_on(self) -> bool:
        lines = self._command("PWR?")
        for ln in lines:
            if ln.startswith("PWR="):
                return ln[4:] in ("01", "02")  # 01 lamp on, 02 warming up
        raise ProtocolError(f"{self.link.label}: 'PWR?' answered {quote(chr(10).join(lines))}; expected 'PWR=NN'")

    def blank(self, on: bool) -> None:
        """A/V mute: the projector shows black without switching off."""
        self._command("MUTE ON" if on else "MUTE OFF")

    def source(self, code: str = "30") -> None:
        """Select an input by its ESC/VP21 code (30 = HDMI1 on most models)."""
        self._command(f"SOURCE {code}")

    def close(self) -> None:
        self.link.close()


class PJLinkProjector:
    """PJLink class 1 control over TCP: ``power``, ``is_on``, ``blank``, ``source``.

    Uses a plain socket, not pyserial's ``socket://``: that handler discards input when it opens, and a
    PJLink projector sends its greeting the moment the connection is made.
    """

    def __init__(self, host: str, port: int = 4352, *, password: str | None = None, timeout: float = 2.0,
                 name: str = "projector") -> None:
        self.label = f"{name} at {host}:{port}"
        self.timeout = timeout
        self._buf = b""
        self._last = "connecting"
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise DeviceDisconnected(f"{self.label}: cannot connect ({exc}); check the address, the network "
                                     "and that PJLink is enabled on the projector") from exc
        try:
            greeting = self._read_line("PJLink greeting")
            if greeting == "PJLINK 0":
                self._prefix = ""
            elif greeting.startswith("PJLINK 1 "):
                if password is None:
                    raise ConfigError(f"{self.label}: the projector asks for a PJLink password; set it in the "
                                      "rig file (devices.projector.control.password)")
                self._prefix = hashlib.md5((greeting.split()[2] + password).encode()).hexdigest()
            else:
                raise ProtocolError(f"{self.label}: expected a PJLink greeting 'PJLINK 0|1', received {quote(greeting)}")
        except Exception:
            self._sock.close()
            raise

    def _read_line(self, what: str) -> str:
        """One line (ended by CR) within the timeout; partial bytes go into the timeout message."""
        deadline = time.monotonic() + self.timeout
        while b"\r" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DeviceTimeout(f"{self.label}: no {what} within {self.timeout:.1f} s after {self._last}; "
                                    f"received {quote(self._buf)}")
            self._sock.settimeout(left)
            try:
                chunk = self._sock.recv(1024)
            except socket.timeout:
                continue
            except OSError as exc:
                raise DeviceDisconnected(f"{self.label}: connection lost while waiting for {what} ({exc})") from exc
            if not chunk:
                raise DeviceDisconnected(f"{self.label}: the projector closed the connection (waiting for {what})")
            self._buf += chunk
            if len(self._buf) > MAX_REPLY_BYTES and b"\r" not in self._buf:
                bad, self._buf = self._buf, b""
                raise ProtocolError(f"{self.label}: expected {what} after {self._last}, received more than "
                                    f"{MAX_REPLY_BYTES} bytes without a CR ({quote(bad)}); is this a PJLink "
                                    "projector?")
        line, self._buf = self._buf.split(b"\r", 1)
        try:
            return line.decode("ascii").strip()
        except UnicodeDecodeError as exc:
            raise ProtocolError(f"{self.label}: non-ASCII reply {quote(line)} to {self._last}; is this a PJLink "
                                "projector?") from exc

    def _command(self, body: str, param: str) -> str:
        self._last = f"'%1{body} {param}'"
        try:
            self._sock.sendall(f"{self._prefix}%1{body} {param}\r".encode("ascii"))
        except OSError as exc:
            raise DeviceDisconnected(f"{self.label}: sending {self._last} failed ({exc})") from exc
        line = self._read_line(f"%1{body} answer")
        if line == "PJLINK ERRA":
            raise CommandError(f"{self.label}: PJLink authentication failed (wrong password)")
        if not line.startswith(f"%1{body}="):
            raise ProtocolError(f"{self.label}: %1{body} answered {quote(line)}; expected '%1{body}=...'")
        value = line.split("=", 1)[1]
        if value.startswith("ERR"):
            meaning = {"ERR1": "undefined command", "ERR2": "parameter out of range",
                       "ERR3": "unavailable now (warming up or off)", "ERR4": "projector failure"}.get(value, "unknown")
            raise CommandError(f"{self.label}: %1{body} {param} was refused: {quote(value)} ({meaning})")
        return value

    def power(self, on: bool) -> None:
        self._command("POWR", "1" if on else "0")

    def is_on(self) -> bool:
        return self._command("POWR", "?") in ("1", "3")  # 1 on, 3 warming up

    def blank(self, on: bool) -> None:
        self._command("AVMT", "31" if on else "30")

    def source(self, code: str = "31") -> None:
        """PJLink input code: 31 = digital input 1 (HDMI 1 on most models)."""
        self._command("INPT", code)

    def close(self) -> None:
        self._sock.close()



def make_projector_control(protocol: str, url: str, **kwargs):
    """From the rig file: ``protocol`` "escvp21" (``url`` a serial port) or "pjlink" (``url`` host[:port])."""
    if protocol == "escvp21":
        return EscVp21Projector(url, kwargs.pop("baud", None) or 9600, **kwargs)
    if protocol == "pjlink":
        host, _, port = url.partition(":")
        kwargs.pop("baud", None)
        return PJLinkProjector(host, int(port or 4352), **kwargs)
    raise ConfigError(f"unknown projector protocol {protocol!r}; known: {', '.join(PROJECTOR_PROTOCOLS)}")
