"""The simulated boards' end of a USB-serial cable: a raw pseudo-terminal a real driver opens by its path.

:class:`PtyPort` can be unplugged (its master side closed: the driver's reads and writes fail with EIO and the
pty's path goes away) and plugged in again (a new pty, so a new path). ``link``: a path kept as a symbolic link
to the current pty while it is plugged in, as udev's ``/dev/serial/by-id/...`` links are, so a driver opened on
it finds the board again after a replug.
"""

from __future__ import annotations

import os
import tty

__all__ = ["PtyPort"]


class PtyPort:
    """A raw pty (``master``: the board's side, ``slave``/``port``: the driver's), plugged in on creation."""

    def __init__(self, link: str | os.PathLike | None = None) -> None:
        self.link = None if link is None else os.fspath(link)
        self.master = self.slave = -1
        self.plug_in()

    def plug_in(self) -> None:
        """A new pty (the old one closed), and ``link`` pointed at it."""
        self.close()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        if self.link is not None:
            tmp = f"{self.link}.tmp"
            if os.path.lexists(tmp):
                os.remove(tmp)
            os.symlink(self.port, tmp)
            os.replace(tmp, self.link)

    def remove_link(self) -> None:
        if self.link is not None and os.path.islink(self.link):
            os.remove(self.link)

    def unplug(self) -> None:
        """Close the master side (the board's thread calls it, not while it reads) and remove ``link``."""
        self.remove_link()
        self._close("master")

    def close(self) -> None:
        """Close both sides and remove ``link`` (idempotent)."""
        self.remove_link()
        self._close("master")
        self._close("slave")

    def _close(self, side: str) -> None:
        fd = getattr(self, side)
        setattr(self, side, -1)
        if fd >= 0:
            try:
                os.close(fd)
            except OSError:
                pass
