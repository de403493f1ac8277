"""The FabScan board's byte protocol, mixed into :class:`rangekit.sim.devices.firmware.SimFirmware`.

57600 baud: every byte is echoed; each line end (``\\r`` or ``\\n``) answers ``>`` once the command is done.
``G01``/``G02 T<steps> F<deg/min>`` block for the move (relative), ``M200`` prints the version, ``M17``-``M22``
are accepted. The faults of the next line (``SimFirmware.inject``) act byte by byte, as the echo does.
"""

from __future__ import annotations

import re
import time

__all__ = ["FabScanProtocol", "FABSCAN_VERSION", "WORD"]

FABSCAN_VERSION = "FabScan v0.1 (rangekit sim)"
#: One word of a G-code line: a letter and its number.
WORD = re.compile(r"([A-Z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


class FabScanProtocol:
    """The FabScan side of :class:`~rangekit.sim.devices.firmware.SimFirmware` (its state, motion model, faults
    and ``_send`` are the firmware's)."""

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
        words = dict(WORD.findall(line.replace(" ", "")))
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
