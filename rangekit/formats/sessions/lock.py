"""One process at a time per session folder: an advisory ``flock`` on ``DIR/.lock``, which holds the pid.

Acquisition and processing hold the lock while they read and write the folder, so a second ``rangekit
scan --resume`` or ``rangekit process`` of a session another process is working on stops at once, naming
the folder and that process's pid, instead of writing the same view twice. The kernel drops the lock when
its process ends (even on SIGKILL or a crash), so a ``.lock`` file left by a dead process is simply
taken over. The lock is re-entrant within a process (``scan`` holds it around acquisition and
processing, which take it again).
"""

from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from rangekit.errors import FileFormatError, RangekitError
from rangekit.io import fsync_folder
from rangekit.formats.sessions.files import LOCK_FILE

__all__ = ["SessionLocked", "session_lock"]

_held: dict[str, list] = {}   # resolved folder -> [fd, depth]


class SessionLocked(RangekitError):
    """Another process is working on the session folder (exit 1)."""


def _holder(path: Path) -> str:
    try:
        text = path.read_text()[:20].strip()
    except (OSError, UnicodeDecodeError):
        return "unknown"
    return text if text.isdigit() else "unknown"


def _open_lock(path: Path) -> int:
    """The lock file opened for writing: never through a symbolic link (it would truncate the file it points
    to) and only a regular file (a FIFO or a device could block or be written into). FileFormatError naming the
    lock file and what to do otherwise."""
    import stat

    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        if os.path.islink(path):
            raise FileFormatError(f"{path}: the session's lock file is a symbolic link (to {os.readlink(path)}); "
                                  "rangekit does not follow it, so as not to write into another file: remove "
                                  f"{path} and try again") from None
        raise FileFormatError(f"{path}: cannot open the session's lock file ({exc.strerror or exc})") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise FileFormatError(f"{path}: the session's lock file is not a regular file (a FIFO, a device or a "
                              f"folder); remove {path} and try again")
    return fd


@contextmanager
def session_lock(folder: str | Path) -> Iterator[None]:
    """Hold the session folder's lock (the folder must exist) for the ``with`` block.

    Raises
    ------
    SessionLocked
        Another process holds it; the message names the folder and that process's pid.
    """
    folder = Path(folder)
    key = str(folder.resolve())
    if key in _held:
        _held[key][1] += 1
        try:
            yield
        finally:
            _held[key][1] -= 1
        return
    path = folder / LOCK_FILE
    fd = _open_lock(path)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise SessionLocked(f"{folder}: the session is in use by another rangekit process (pid {_holder(path)}, "
                            f"lock {path}); wait until it ends, or stop it and try again") from None
    except BaseException:
        os.close(fd)
        raise
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        os.fsync(fd)
        fsync_folder(folder)
        _held[key] = [fd, 1]
        yield
    finally:
        _held.pop(key, None)
        os.close(fd)   # releases the flock
