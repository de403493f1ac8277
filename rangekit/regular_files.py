"""Reading a file that must be a regular file: the one reader of image files, frames and headers.

A FIFO, a device (``/dev/urandom``) or a folder where a file is expected could block a read forever or never
end; a path is handed to the system as bytes, so a name that is not valid UTF-8 is read like any other.
"""

from __future__ import annotations

import os
from pathlib import Path

from rangekit.errors import FileFormatError

__all__ = ["read_regular_file", "check_regular_file"]


def read_regular_file(path: str | Path, *, what: str = "a file", limit: int | None = None) -> bytes:
    """The bytes of ``path``, which must be a regular file (a FIFO, a device such as ``/dev/urandom`` or a
    folder is refused by name: reading one could block or never end); at most ``limit`` bytes when given.
    The path is handed to the system as it is (``os.fsencode``: any bytes, valid UTF-8 or not), never to a
    library that converts it. FileFormatError names the file and what was expected."""
    import stat

    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise FileFormatError(f"{path}: not found; expected {what}") from None
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot be opened ({exc.strerror or exc}); expected {what}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileFormatError(f"{path}: is {_kind(mode)}; expected {what} (a regular file)")
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read() if limit is None else f.read(limit)
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot be read ({exc.strerror or exc}); expected {what}") from None
    finally:
        os.close(fd)


def _kind(mode: int) -> str:
    import stat

    return ("a folder" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
            "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "not a regular file")


def check_regular_file(path: str | Path, *, what: str = "a file") -> None:
    """FileFormatError unless ``path`` (links followed) is a regular file: a missing path, a folder, a FIFO
    (reading it blocks) or a device such as ``/dev/urandom`` (reading it never ends) are named. For readers
    that open the file through a library (plyfile, trimesh, pye57) after this check."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise FileFormatError(f"{path}: not found; expected {what}") from None
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot be read ({exc.strerror or exc}); expected {what}") from None
    if not stat.S_ISREG(mode):
        raise FileFormatError(f"{path}: is {_kind(mode)}; expected {what} (a regular file)")
