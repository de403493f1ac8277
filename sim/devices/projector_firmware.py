"""Simulated projector control peers that speak bytes: an ESC/VP21 projector on a pty and a PJLink
server on a loopback TCP port. ``silent=True`` makes them never answer (for timeout tests)."""

from __future__ import annotations

import hashlib
import os
import select
import socket
import threading
import tty

__all__ = ["SimEscVp21", "SimPJLink"]


class SimEscVp21:
    """An Epson ESC/VP21 projector on a pty: ``.port`` for the driver; state in ``power``, ``mute``, ``source``."""

    def __init__(self, *, silent: bool = False) -> None:
        self.silent = silent
        self.power, self.mute, self.source = False, False, "30"
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _reply(self, line: str) -> bytes:
        if line == "":
            return b":"
        if line == "PWR ON":
            self.power = True
        elif line == "PWR OFF":
            self.power = False
        elif line == "PWR?":
            return (b"PWR=01\r:" if self.power else b"PWR=00\r:")
        elif line in ("MUTE ON", "MUTE OFF"):
            if not self.power:
                return b"ERR\r:"
            self.mute = line == "MUTE ON"
        elif line.startswith("SOURCE "):
            self.source = line.split()[1]
        else:
            return b"ERR\r:"
        return b":"

    def _run(self) -> None:
        buf = b""
        while not self._stop.is_set():
            r, _, _ = select.select([self._master], [], [], 0.05)
            if not r:
                continue
            try:
                buf += os.read(self._master, 1024)
            except OSError:
                return
            while b"\r" in buf:
                line, buf = buf.split(b"\r", 1)
                if not self.silent:
                    os.write(self._master, self._reply(line.decode("ascii", "replace").strip()))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


class SimPJLink:
    """A PJLink class 1 server on 127.0.0.1 (``.port``); optional password; one client at a time."""

    def __init__(self, *, password: str | None = None, silent: bool = False) -> None:
        self.password, self.silent = password, silent
        self.power, self.avmt, self.input = "0", "30", "31"
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.listen(1)
        self._sock.settimeout(0.1)
        self.port = self._sock.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _answer(self, cmd: str, seed: str) -> str:
        if self.password is not None:
            digest = hashlib.md5((seed + self.password).encode()).hexdigest()
            if not cmd.startswith(digest):
                return "PJLINK ERRA"
            cmd = cmd[len(digest):]
        if not cmd.startswith("%1") or " " not in cmd:
            return "%1XXXX=ERR1"
        body, param = cmd[2:].split(" ", 1)
        if body == "POWR":
            if param == "?":
                return f"%1POWR={self.power}"
            if param in ("0", "1"):
                self.power = param
                return "%1POWR=OK"
            return "%1POWR=ERR2"
        if body in ("AVMT", "INPT"):
            if self.power != "1":
                return f"%1{body}=ERR3"
            setattr(self, "avmt" if body == "AVMT" else "input", param)
            return f"%1{body}=OK"
        return f"%1{body}=ERR1"

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except (socket.timeout, OSError):
                continue
            seed = "498e4a67"
            with conn:
                if self.silent:
                    self._stop.wait(5)
                    continue
                conn.sendall(b"PJLINK 0\r" if self.password is None else f"PJLINK 1 {seed}\r".encode())
                buf = b""
                conn.settimeout(0.1)
                while not self._stop.is_set():
                    try:
                        data = conn.recv(1024)
                    except socket.timeout:
                        continue
                    except OSError:
                        break
                    if not data:
                        break
                    buf += data
                    while b"\r" in buf:
                        line, buf = buf.split(b"\r", 1)
                        conn.sendall(self._answer(line.decode("ascii", "replace"), seed).encode() + b"\r")

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1)
        self._sock.close()
