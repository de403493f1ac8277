"""Count the files read in folders while code runs, from the kernel's side (inotify): every open for
reading is counted, whoever opens it (Python, OpenCV, Open3D, numpy), so a test can say "each frame was
read once" and "nothing written was read back".

    with FileReads([folder, *view_folders]) as reads:
        ...
    reads.count("view_000/000.png")     # read-only opens closed, by path relative to the first folder
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import struct
import threading
from collections import Counter
from pathlib import Path

_IN_CLOSE_NOWRITE = 0x00000010   # a file opened read-only was closed: one read of it
_IN_ISDIR = 0x40000000
_IN_Q_OVERFLOW = 0x00004000
_EVENT = struct.Struct("iIII")


class FileReads:
    """Read-only opens of the files directly in ``folders`` (not their sub-folders), counted by path relative to
    ``folders[0]``, from entering the context to leaving it."""

    def __init__(self, folders) -> None:
        self._folders = [Path(f).resolve() for f in folders]
        self._root = self._folders[0]
        self.reads: Counter = Counter()
        self._libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)

    def __enter__(self) -> "FileReads":
        self._fd = self._libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
        if self._fd < 0:
            raise OSError(ctypes.get_errno(), "inotify_init1")
        self._where = {}
        for folder in self._folders:
            wd = self._libc.inotify_add_watch(self._fd, str(folder).encode(), _IN_CLOSE_NOWRITE)
            if wd < 0:
                raise OSError(ctypes.get_errno(), f"inotify_add_watch {folder}")
            self._where[wd] = folder
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._drain, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self._read_events()
        os.close(self._fd)

    def count(self, relative: str) -> int:
        return self.reads[relative]

    def _drain(self) -> None:
        while not self._stop.wait(0.05):
            self._read_events()

    def _read_events(self) -> None:
        while True:
            try:
                data = os.read(self._fd, 1 << 16)
            except BlockingIOError:
                return
            at = 0
            while at < len(data):
                wd, mask, _, size = _EVENT.unpack_from(data, at)
                name = data[at + _EVENT.size: at + _EVENT.size + size].split(b"\0", 1)[0].decode()
                at += _EVENT.size + size
                if mask & _IN_Q_OVERFLOW:
                    raise AssertionError("inotify queue overflowed: reads were lost")
                if mask & _IN_ISDIR or not name or wd not in self._where:
                    continue
                self.reads[(self._where[wd] / name).relative_to(self._root).as_posix()] += 1
